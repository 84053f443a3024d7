"""Numbers -> decisions -> motor: Kalman MI trend, supervisor, mill protocol, driver, emulator.

Imports nothing from ``vision``, ``sim`` or ``twin``.
"""
