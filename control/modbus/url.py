"""The ``modbus:`` mill URL and a mixer config's ``[drive]`` table (pure): what
``control.modbus.link.ModbusMill`` opens.

URL (everything after ``?`` belongs to the Modbus layer)::

    modbus:/dev/ttyUSB0?profile=delta-ms300&unit=1&baud=19200&parity=E
    modbus:socket://127.0.0.1:5020?profile=abb-acs&unit=1&hz_per_rpm=12.5

Keys: ``profile`` (shipped name or a .toml path; required), ``unit`` (1..247, default 1),
``baud`` (19200), ``parity`` (N/E/O, default E), ``stopbits`` (1/2), ``hz_per_rpm`` (motor
Hz per drum rpm; default the profile's), ``max_hz`` (highest setpoint this link writes;
default the profile's), ``comm_loss_limit`` (longest comm-loss trip accepted, s; default
:data:`COMM_LOSS_LIMIT_S`), ``override=comm-loss`` (start and speed up a drive whose trip is
disabled, too long or unreadable: logged as ``safety_override``).
"""

from __future__ import annotations

from dataclasses import dataclass
from urllib.parse import parse_qsl

from control.errors import ControlError, check_number

SCHEME = "modbus:"
COMM_LOSS_LIMIT_S = 5.0
"""Longest comm-loss trip time (s) the link accepts without an override: the loop's own
limit for a mill nobody controls any more (the line protocol's board watchdog is 1 s)."""

_KEYS = ("profile", "unit", "baud", "parity", "stopbits", "hz_per_rpm", "max_hz", "comm_loss_limit", "override")


@dataclass(frozen=True)
class ModbusUrl:
    """A parsed ``modbus:`` mill URL (see module doc)."""

    port: str
    profile: str
    unit: int = 1
    baud: int = 19200
    parity: str = "E"
    stopbits: int = 1
    hz_per_rpm: float | None = None
    max_hz: float | None = None
    comm_loss_limit_s: float = COMM_LOSS_LIMIT_S
    override: bool = False


def is_modbus_url(url: str) -> bool:
    return url.startswith(SCHEME)


def parse_modbus_url(url: str) -> ModbusUrl:
    """Parse a ``modbus:`` URL (pure); one-line ``ControlError`` naming the bad part."""
    if not is_modbus_url(url):
        raise ControlError(f"not a modbus: URL: {url!r}")
    port, _, query = url[len(SCHEME):].partition("?")
    if not port:
        raise ControlError(f"modbus URL {url!r} names no port (modbus:/dev/ttyUSB0?profile=...)")
    q: dict[str, str] = {}
    for k, v in parse_qsl(query, keep_blank_values=True):
        if k not in _KEYS:
            raise ControlError(f"unknown key {k!r} in modbus URL (known: {', '.join(_KEYS)})")
        q[k] = v
    if "profile" not in q:
        raise ControlError("modbus URL needs profile=NAME (delta-ms300, abb-acs, siemens-v20, invertek-e3, generic)")

    def integer(key: str, default: int, lo: int, hi: int) -> int:
        try:
            v = int(q.get(key, default))
        except ValueError:
            v = lo - 1
        if not lo <= v <= hi:
            raise ControlError(f"modbus URL: {key} must be an integer in {lo}..{hi} (got {q.get(key)!r})")
        return v

    def number(key: str, default: float | None, **bounds: float) -> float | None:
        return default if key not in q else check_number(f"modbus URL: {key}", q[key], **bounds)

    parity = q.get("parity", "E").upper()
    if parity not in ("N", "E", "O"):
        raise ControlError(f"modbus URL: parity must be N, E or O (got {q['parity']!r})")
    override = q.get("override", "")
    if override not in ("", "comm-loss"):
        raise ControlError(f"modbus URL: override must be 'comm-loss' (got {override!r})")
    return ModbusUrl(
        port=port,
        profile=q["profile"],
        unit=integer("unit", 1, 1, 247),
        baud=integer("baud", 19200, 300, 4_000_000),
        parity=parity,
        stopbits=integer("stopbits", 1, 1, 2),
        hz_per_rpm=number("hz_per_rpm", None, above=0.0),
        max_hz=number("max_hz", None, above=0.0, at_most=600.0),
        comm_loss_limit_s=number("comm_loss_limit", COMM_LOSS_LIMIT_S, above=0.0) or COMM_LOSS_LIMIT_S,
        override=override == "comm-loss",
    )


DRIVE_KEYS = ("hz_per_rpm",)
"""Keys of a mixer config's ``[drive]`` table (the drive behind a ``modbus:`` mill URL)."""


def drive_hz_per_rpm(table: object, source: str) -> float | None:
    """``hz_per_rpm`` (motor Hz per drum rpm) of a config's ``[drive]`` table, None when the
    table or the key is absent (pure); one-line ``ControlError`` for an unknown key or a bad value."""
    if table is None or table == {}:
        return None
    if not isinstance(table, dict):
        raise ControlError(f"{source}: [drive] must be a table (hz_per_rpm = ...)")
    unknown = sorted(set(table) - set(DRIVE_KEYS))
    if unknown:
        raise ControlError(f"{source}: unknown key(s) {unknown} in [drive] (allowed: {', '.join(DRIVE_KEYS)})")
    if "hz_per_rpm" not in table:
        return None
    v = table["hz_per_rpm"]
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ControlError(f"{source}: [drive] hz_per_rpm must be a number (got {v!r})")
    return check_number(f"{source}: [drive] hz_per_rpm", float(v), above=0.0, at_most=1e4)


def config_mill_url(url: str, drive_table: object, source: str) -> str:
    """The mill URL a run (or ``drumtwin mill --config``) opens, given the config's ``[drive]``
    table (pure): its ``hz_per_rpm`` is written into a ``modbus:`` URL, the one place the link
    reads it (the run's ``start`` event shows that URL). A URL that already carries
    ``hz_per_rpm`` must agree (within 1e-6), else one-line ``ControlError`` naming both; a
    line-protocol board's URL refuses it (that board takes rpm, not Hz). No value: the URL unchanged."""
    hz_per_rpm = drive_hz_per_rpm(drive_table, source)
    if hz_per_rpm is None:
        return url
    if not is_modbus_url(url):
        raise ControlError(f"{source}: [drive] hz_per_rpm is for a drive (a modbus: mill URL), not {url!r}")
    given = parse_modbus_url(url).hz_per_rpm
    if given is not None:
        if abs(given - hz_per_rpm) > 1e-6 * max(given, hz_per_rpm):
            raise ControlError(f"hz_per_rpm: the mill URL says {given:g}, {source} [drive] says {hz_per_rpm:g}:"
                               " give it in one place (or make them agree)")
        return url
    return url + ("&" if "?" in url else "?") + f"hz_per_rpm={hz_per_rpm!r}"


__all__ = ["COMM_LOSS_LIMIT_S", "DRIVE_KEYS", "SCHEME", "ModbusUrl", "config_mill_url", "drive_hz_per_rpm",
           "is_modbus_url", "parse_modbus_url"]
