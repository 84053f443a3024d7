"""A monolayer's end plates in the calibration (issue 39 item 3), on a known slope field.

The twin is replaced by an analytic slope field of (sliding, rolling, end-plate friction)
(``twin_surface`` patched in ``sim.calibrate``), so each decision is checked against a value
computed by hand: the plates searched only in a monolayer, from no plate friction up to
``END_LOAD_MAX W / r``, only beyond the plane's top, and the error naming the friction that
would have to leave its range. The real twins are in ``test_calibrate_reach.py``.
"""

from __future__ import annotations

import math
from dataclasses import replace

import pytest

import sim.calibrate as cal_mod
from sim.calibrate import (
    CONFIRM_EVALS,
    END_LOAD_MAX,
    HIGH_EDGE,
    PLATE_EDGE,
    PLATES,
    calibrate,
    end_friction_max,
    path_point,
    reachable_range,
)
from sim.calibrate_slope import Measured
from sim.errors import SimError
from sim.mixer import Friction, Mixer, ParticleKind, Shape, paper_mixer
from sim.recipe import DrumSpec

# a monolayer of 10 mm discs 3 mm thick: the plates 3 mm apart, r / W = 5 / 3
MONO = Mixer(DrumSpec(0.25, 0.003), (ParticleKind("blue", Shape("disc", 0.010), count=100, thickness_m=0.003),
                                     ParticleKind("white", Shape("disc", 0.010), count=100, thickness_m=0.003)),
             monolayer=True)
E_MAX = END_LOAD_MAX * 0.003 / 0.005  # 0.048


def plane(f: float, r: float) -> float:
    """20 deg at the least-friction corner, +10 deg per decade of sliding friction, +15 per unit rolling:
    the high edge peaks at (1, 1) with 48 deg (the diagonal to it: 20 + 28 u)."""
    return 20.0 + 10.0 * math.log10(f / 0.05) / math.log10(20.0) * 1.3 + 15.0 * r


class Field:
    """A fake ``twin_surface`` of (sliding, rolling, end-plate friction): the plane's slope plus
    ``plates(e)`` deg (by default 12 deg per ``E_MAX``; None: the twin's own plates, a deep drum's: in the plane)."""

    def __init__(self) -> None:
        self.plates = lambda e: 12.0 * e / E_MAX
        self.plane = plane
        self.calls: list[tuple[float, float, float | None]] = []
        self.spins: list[float] = []

    def __call__(self, friction: float, rolling: float, rpm: float, **kw) -> tuple[float, float]:
        e = kw.get("end_friction")
        self.calls.append((friction, rolling, e))
        self.spins.append(kw.get("spin_up_s", 3.0))
        return -(self.plane(friction, rolling) + (0.0 if e is None else self.plates(e))), 0.0


@pytest.fixture
def field(monkeypatch) -> Field:
    f = Field()
    monkeypatch.setattr(cal_mod, "twin_surface", f)
    return f


def test_only_a_monolayers_plates_are_searched_and_by_its_geometry():
    assert end_friction_max(MONO) == pytest.approx(E_MAX, rel=1e-12)
    thick = replace(MONO, drum=DrumSpec(0.25, 0.010))  # plates a disc's diameter apart: 10 / 5 of it
    assert end_friction_max(thick) == pytest.approx(END_LOAD_MAX * 2.0, rel=1e-12)
    assert end_friction_max(paper_mixer()) == 0.0  # a deep drum: Taberlet's law with the wall's friction
    assert end_friction_max(None) == 0.0  # the paper's drum + recipe
    assert end_friction_max(MONO, {"end_friction": 0.0}) == 0.0  # fixed by the caller: not searched
    assert end_friction_max(MONO, {"end_friction": None}) == pytest.approx(E_MAX)


def test_a_monolayers_range_runs_the_plane_without_plates_then_the_plates_at_the_planes_top(field):
    lo, hi = reachable_range(5.0, mixer=MONO)
    plane_calls = [(0.05, 0.0, 0.0)] + [(f, 1.0, 0.0) for f in HIGH_EDGE]
    assert PLATE_EDGE == (0.5, 1.0)
    assert field.calls == [*plane_calls, (1.0, 1.0, pytest.approx(0.5 * E_MAX)), (1.0, 1.0, pytest.approx(E_MAX))]
    assert (lo, hi) == pytest.approx((20.0, plane(1.0, 1.0) + 12.0))


def test_a_deep_drums_range_leaves_the_plates_to_the_twin(field):
    reachable_range(5.0, mixer=paper_mixer())
    assert field.calls == [(0.05, 0.0, None)] + [(f, 1.0, None) for f in HIGH_EDGE]


def test_a_slope_the_plane_reaches_is_fitted_with_no_plate_friction(field):
    cal = calibrate(-30.0, 5.0, mixer=MONO)
    assert cal.end_friction == 0.0 and cal.path == "diagonal" and cal.end_friction_max == pytest.approx(E_MAX)
    assert all(e == 0.0 for _, _, e in field.calls[:4] + field.calls[6:])  # every plane run without plates
    u = 10.0 / (plane(1.0, 1.0) - 20.0)  # linear along the diagonal: the first regula falsi step
    assert (cal.friction, cal.rolling) == pytest.approx(path_point(u), abs=1e-12)
    assert cal.twin_slope_deg == pytest.approx(-30.0) and cal.evaluations == 1 + len(HIGH_EDGE) + len(PLATE_EDGE) + 1
    assert cal.twin_kwargs() == {"friction": cal.friction, "rolling": cal.rolling, "end_friction": 0.0}


def test_a_slope_beyond_the_planes_top_takes_the_plate_friction_it_needs(field):
    top = plane(1.0, 1.0)  # 48 deg, the plates add 12 deg per E_MAX linearly
    cal = calibrate(top + 3.0, 5.0, mixer=MONO)
    assert cal.path == PLATES and (cal.friction, cal.rolling) == (1.0, 1.0)
    assert cal.end_friction == pytest.approx(E_MAX * 3.0 / 12.0, rel=1e-9)
    assert cal.residual_deg == pytest.approx(0.0, abs=1e-9)
    assert cal.history[-1] == pytest.approx((1.0, 1.0, cal.end_friction, top + 3.0))


def test_plates_that_do_not_steepen_the_bed_leave_the_range_to_the_plane(field):
    field.plates = lambda e: -5.0 * e / E_MAX  # plate friction makes this bed flatter (it turns with its plates)
    lo, hi = reachable_range(5.0, mixer=MONO)
    assert (lo, hi) == pytest.approx((20.0, plane(1.0, 1.0)))
    cal = calibrate(hi - 1.0, 5.0, mixer=MONO)
    assert cal.path == "diagonal" and cal.end_friction == 0.0


def test_plates_whose_bed_stands_lower_at_the_most_friction_take_the_best_of_the_edge(field):
    field.plates = lambda e: 20.0 * min(e, E_MAX - e) / E_MAX  # +10 deg at half the most, 0 at the most
    assert reachable_range(5.0, mixer=MONO)[1] == pytest.approx(plane(1.0, 1.0) + 10.0)
    cal = calibrate(plane(1.0, 1.0) + 5.0, 5.0, mixer=MONO)  # half way up the leg to half the most
    assert cal.path == PLATES and cal.end_friction == pytest.approx(0.25 * E_MAX, rel=1e-9)


def test_each_end_of_the_range_names_the_friction_that_would_have_to_leave_its_range(field):
    box = f"(sliding friction 0.05-1, rolling friction 0-1, end-plate friction 0-{E_MAX:.3g})"
    with pytest.raises(SimError) as low:
        calibrate(15.0, 5.0, mixer=MONO)
    assert str(low.value) == (f"target slope 15.0 deg is outside the twin's reachable range 20.0-60.0 deg at 5 rpm "
                              f"{box}: it needs sliding friction below 0.05")
    with pytest.raises(SimError) as high:
        calibrate(70.0, 5.0, mixer=MONO)
    assert str(high.value).endswith(f"{box}: it needs end-plate friction above {E_MAX:.3g}, "
                                    "where a monolayer turns with its plates")
    with pytest.raises(SimError) as deep:
        calibrate(89.0, 5.0, mixer=paper_mixer())
    assert str(deep.value).endswith("(sliding friction 0.05-1, rolling friction 0-1): "
                                    "it needs rolling friction above 1")
    with pytest.raises(SimError, match=r"rolling friction 0-1\): it needs rolling friction above 1$"):
        calibrate(89.0, 5.0, mixer=MONO, end_friction=0.0)  # plates fixed by the caller: not searched


def test_a_fixed_plate_friction_reaches_every_run_and_the_result(field):
    cal = calibrate(40.0, 5.0, mixer=MONO, end_friction=0.01)
    assert {e for _, _, e in field.calls} == {0.01}
    assert cal.end_friction == 0.01 and cal.end_friction_max == 0.0 and cal.path == "diagonal"


def test_a_slow_drum_turns_a_quarter_turn_before_each_runs_slope_counts(field):
    from sim.calibrate import default_spin_up_s

    assert default_spin_up_s(10.0) == 3.0 and default_spin_up_s(-2.0) == pytest.approx(7.5)
    with pytest.raises(SimError):
        calibrate(80.0, 2.0, mixer=MONO)  # the range runs only
    reachable_range(2.0, mixer=MONO)
    calibrate(30.0, 2.0, mixer=MONO, spin_up_s=1.0)
    spins = field.spins
    assert spins[:2 * 6] == [pytest.approx(7.5)] * 12 and set(spins[12:]) == {1.0}


def test_a_deep_drums_own_plate_friction_is_kept_and_reported(field):
    deep = replace(paper_mixer(), friction=Friction(end_plates=0.1))  # e.g. [drum.friction] end_plates in the config
    cal = calibrate(30.0, 5.0, mixer=deep)
    assert all(e is None for _, _, e in field.calls)  # the twin takes the mixer's (make_twin)
    assert cal.end_friction == 0.1 and cal.end_friction_max == 0.0


def test_the_plates_leg_starts_at_the_planes_top_wherever_it_is(field):
    field.plane = lambda f, r: plane(min(f, 0.5), r) - 10.0 * max(math.log10(f / 0.5), 0.0)  # top at (0.5, 1)
    reachable_range(5.0, mixer=MONO)
    assert field.calls[4:] == [(0.5, 1.0, pytest.approx(0.5 * E_MAX)), (0.5, 1.0, pytest.approx(E_MAX))]
    cal = calibrate(plane(0.5, 1.0) + 3.0, 5.0, mixer=MONO)
    assert cal.path == PLATES and (cal.friction, cal.rolling) == (0.5, 1.0)
    assert cal.end_friction == pytest.approx(E_MAX * 3.0 / 12.0, rel=1e-9)


def test_plates_that_add_nothing_are_no_leg_and_a_target_at_the_planes_top_is_the_planes(field):
    field.plates = lambda e: 0.0
    top = plane(1.0, 1.0)
    cal = calibrate(top + 0.5, 5.0, mixer=MONO)  # within the grace above the plane's top: its high point
    assert cal.path == "diagonal" and cal.end_friction == 0.0 and cal.residual_deg == pytest.approx(-0.5)
    field.plates = lambda e: 12.0 * e / E_MAX
    cal = calibrate(top, 5.0, mixer=MONO)  # exactly the plane's top: the plane's, no plate friction
    assert cal.path == "diagonal" and (cal.friction, cal.rolling, cal.end_friction) == (1.0, 1.0, 0.0)


def test_a_range_with_the_plates_fixed_by_the_caller_runs_the_plane_only(field):
    lo, hi = reachable_range(5.0, mixer=MONO, end_friction=0.01)
    assert field.calls == [(0.05, 0.0, 0.01)] + [(f, 1.0, 0.01) for f in HIGH_EDGE]
    fixed = 12.0 * 0.01 / E_MAX  # the plates' 2.5 deg in every run
    assert (lo, hi) == pytest.approx((20.0 + fixed, plane(1.0, 1.0) + fixed))


def test_progress_counts_the_plates_and_the_confirming_runs_in_the_whole_budget(field):
    seen: list[tuple[int, int]] = []
    calibrate(-30.0, 5.0, mixer=MONO, confirm_evals=CONFIRM_EVALS, measure=lambda f, r, e: Measured(31.0, 0.1),
              progress=lambda i, n: seen.append((i, n)))
    total = 1 + len(HIGH_EDGE) + len(PLATE_EDGE) + 8 + CONFIRM_EVALS
    assert CONFIRM_EVALS == 3 and [n for _, n in seen] == [total] * len(seen)
    assert [i for i, _ in seen] == list(range(1, len(seen) + 1)) and len(seen) > 1 + len(HIGH_EDGE) + len(PLATE_EDGE)
