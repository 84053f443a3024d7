"""``drumtwin calibrate`` on the pymunk engine (a shaped mixer): its reachable range, exit 2 outside it."""

from __future__ import annotations

import json
import re
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
def test_calibrate_end_friction_sets_the_plates_of_the_twin_runs(cli_once):
    # the monolayer rig with the default (Taberlet) plates stands steep over the whole search; without
    # plate friction (--end-friction 0) the whole range lies below that: the option reaches the twin runs
    plates = cli_once(*OUTSIDE)
    assert_one_line_error(plates, "outside the twin's reachable range")
    none = cli("calibrate", "--config", CUTDISC_RIG, "--rpm", "10", "--slope-deg", "89", "--end-friction", "0",
               *SHORT)
    assert_one_line_error(none, "outside the twin's reachable range")
    (lo_p, hi_p), (lo_0, hi_0) = _range(plates.err), _range(none.err)
    assert hi_0 < lo_p, (lo_0, hi_0, lo_p, hi_p)
    assert lo_0 < 25.0 < hi_0  # the low end of issue 20's 25-45 deg is inside it
    # a value out of [0, 5] is refused before any twin runs
    assert_one_line_error(cli("calibrate", "--config", CUTDISC_RIG, "--rpm", "10", "--slope-deg", "30",
                              "--end-friction", "-0.1"), "--end-friction")
