"""Calibration refuses targets below its reachable range too, not only above it (issue 27)."""

from __future__ import annotations

import pytest

from sim.calibrate import calibrate
from sim.errors import SimError
from tests.cli import cli


def test_a_target_below_the_reachable_range_is_an_error_that_names_the_range():
    with pytest.raises(SimError, match=r"target slope 3\.0 deg is outside the twin's reachable range "
                                       r"(\d+\.\d)-(\d+\.\d) deg at 10 rpm") as exc:
        calibrate(3.0, 10.0, spin_up_s=0.5, window_s=0.5)
    lo = float(exc.value.args[0].split("range ")[1].split("-")[0])
    assert lo > 3.0 + 0.5  # the low corner is well above the target, so a silent fit would be > 0.5 deg off


def test_calibrate_cli_below_range_is_exit_2_with_one_line():
    res = cli("calibrate", "--slope-deg", 3, "--rpm", 10, "--spin-up-s", 0.5, "--window-s", 0.5)
    assert res.code == 2
    lines = [ln for ln in res.err.splitlines() if ln.strip()]
    assert len(lines) == 1 and "outside the twin's reachable range" in lines[0]
