"""``drumtwin calibrate`` on the pymunk engine (a shaped mixer): its reachable range, exit 2 outside it."""

from __future__ import annotations

import json
import re
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.cli import assert_one_line_error, cli

REPO = Path(__file__).resolve().parents[2]
CUTDISC_RIG = REPO / "configs" / "pmma-cutdisc.toml"
SHORT = ("--spin-up-s", "0.5", "--window-s", "0.5", "--dt-ms", "2")  # short twin runs: the range, not its value
# 89 deg is outside the rig's range: the command runs the range's twin runs and says the range. Both
# tests read the one run of it (``cli_once``, tests/conftest.py; one xdist group: one worker, one run).
OUTSIDE = ("calibrate", "--config", CUTDISC_RIG, "--rpm", "10", "--slope-deg", "89", *SHORT)
pytestmark = pytest.mark.xdist_group("pymunk-cli")


@pytest.fixture(scope="module", autouse=True)
def same_twin_run_once() -> Iterator[dict[str, int]]:
    """``sim.calibrate.twin_surface`` memoised for this module, keyed on every argument: the calls below
    ask for the same seeded twin runs again (the range's six runs before the search inside it, the plane's
    four with ``--end-friction 0``), and a pymunk run of the rig costs ~1 s. A call whose arguments differ
    in anything runs the twin, so a range that comes out the same still says the CLI asked for the same
    runs; that a repeated run is bit-exact is ``test_pymunk_twin.py``'s (cut discs, other addresses)."""
    import sim.calibrate

    real = sim.calibrate.twin_surface
    runs: dict[str, tuple[float, float]] = {}
    calls = {"ran": 0, "reused": 0}

    def once(friction: float, rolling: float, rpm: float, **kw: object) -> tuple[float, float]:
        key = repr((friction, rolling, rpm, sorted(kw.items())))
        if key in runs:
            calls["reused"] += 1
        else:
            calls["ran"] += 1
            runs[key] = real(friction, rolling, rpm, **kw)
        return runs[key]

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(sim.calibrate, "twin_surface", once)
        yield calls


@pytest.mark.slow
@pytest.mark.timeout(900)
def test_calibrate_runs_the_cut_disc_rig_on_pymunk_says_its_range_and_exits_2_outside_it(cli_once):
    # the DEM cannot hold cut discs: asking for it is refused before anything runs
    assert_one_line_error(cli("calibrate", "--config", CUTDISC_RIG, "--engine", "dem", "--rpm", "10",
                              "--slope-deg", "30"), "compiled DEM", "pymunk")
    r = cli_once(*OUTSIDE)
    assert_one_line_error(r, "outside the twin's reachable range", "at 10 rpm")
    m = re.search(r"range (\d+\.\d)-(\d+\.\d) deg", r.err)
    assert m, r.err
    lo, hi = float(m.group(1)), float(m.group(2))
    assert 0.0 < lo < hi < 89.0
    # a target inside the range calibrates on pymunk, and the range is the same (seeded, bit-exact runs: the
    # post-step pass orders a pair's contacts with equal normals by impulse and depth, not by memory layout)
    target = round(0.5 * (lo + hi), 1)
    r = cli("calibrate", "--config", CUTDISC_RIG, "--rpm", "10", "--slope-deg", str(-target), "--max-evals", "2",
            *SHORT, "--json")
    assert r.code == 0, r.err
    out = json.loads(r.out)
    assert out["engine"] == "pymunk"
    assert out["range_deg"] == pytest.approx([lo, hi], abs=0.051)  # the message prints one decimal
    assert lo - 1.0 <= abs(out["twin_slope_deg"]) <= hi + 1.0 and out["twin_slope_deg"] < 0
    assert 0.05 <= out["friction"] <= 1.0 and 0.0 <= out["rolling"] <= 1.0


def _range(err: str) -> tuple[float, float]:
    m = re.search(r"range (\d+\.\d)-(\d+\.\d) deg", err)
    assert m, err
    return float(m.group(1)), float(m.group(2))


@pytest.mark.slow
@pytest.mark.timeout(900)
def test_calibrate_searches_a_monolayers_plates_and_end_friction_fixes_them(cli_once):
    # the monolayer rig's plates are searched from no plate friction up (issue 39): the default range
    # starts where --end-friction 0 (plates fixed, not searched) starts and reaches beyond its top; a
    # fixed plate friction reaches every twin run (its whole range lies higher)
    searched = cli_once(*OUTSIDE)
    assert_one_line_error(searched, "outside the twin's reachable range", "needs end-plate friction above")
    none = cli("calibrate", "--config", CUTDISC_RIG, "--rpm", "10", "--slope-deg", "89", "--end-friction", "0",
               *SHORT)
    assert_one_line_error(none, "outside the twin's reachable range", "needs rolling friction above 1")
    grip = cli("calibrate", "--config", CUTDISC_RIG, "--rpm", "10", "--slope-deg", "89", "--end-friction", "0.02",
               *SHORT)
    (lo_s, hi_s), (lo_0, hi_0), (lo_g, _) = _range(searched.err), _range(none.err), _range(grip.err)
    assert lo_s == pytest.approx(lo_0, abs=0.051)  # the same run: the least-friction corner without plates
    assert hi_s > hi_0 + 3.0, (hi_s, hi_0)  # the plates take the slope beyond the plane's top
    assert lo_g > lo_0 + 5.0, (lo_g, lo_0)
    assert lo_0 < 25.0 < hi_0  # the low end of issue 20's 25-45 deg is inside it
    # a value out of [0, 5] is refused before any twin runs
    assert_one_line_error(cli("calibrate", "--config", CUTDISC_RIG, "--rpm", "10", "--slope-deg", "30",
                              "--end-friction", "-0.1"), "--end-friction")
