"""Frequency inverters over Modbus RTU: drive profiles (register maps as data), the Modbus
mill link (the same interface as ``control.driver.MillClient``) and a pymodbus drive
emulator. See ``docs/drives.md``."""
