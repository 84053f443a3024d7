"""The one exception type of ``sim``: bad input or a broken environment, said in one line.

Also the range checks that turn bad numbers into that one line (``check_number``, ``check_seed``).
"""

import math


class SimError(ValueError):
    """A clear, user-facing error of the ``sim`` package (the CLI prints it as one line)."""


MAX_SEED = 2**32  # seeds are 0 <= seed < 2**32 (numpy's SeedSequence takes more, the CLI does not)


def check_number(
    name: str, value: object, lo: float, hi: float, *, lo_open: bool = False, integer: bool = False
) -> float:
    """``value`` as a finite number in ``[lo, hi]`` (``(lo, hi]`` with ``lo_open``), else a one-line
    SimError naming ``name`` (an option such as ``--duration``) and the allowed range."""
    try:
        v = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        v = math.nan
    ok = math.isfinite(v) and (v > lo if lo_open else v >= lo) and v <= hi
    if ok and integer and not v.is_integer():
        ok = False
    if not ok:
        kind = "an integer" if integer else "a number"
        rng = f"{'(' if lo_open else '['}{lo:g}, {hi:g}]"
        raise SimError(f"{name} must be {kind} in {rng} (got {value})")
    return v


def check_seed(name: str, seed: object) -> int:
    """A seed as an int with ``0 <= seed < 2**32``, else a one-line SimError naming ``name``."""
    if isinstance(seed, bool) or (not isinstance(seed, (int,)) and not (isinstance(seed, float) and seed.is_integer())):
        raise SimError(f"{name} must be an integer with 0 <= seed < 2**32 (got {seed!r})")
    s = int(seed)
    if not 0 <= s < MAX_SEED:
        raise SimError(f"{name} must be an integer with 0 <= seed < 2**32 (got {s})")
    return s
