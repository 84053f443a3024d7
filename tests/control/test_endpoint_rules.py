"""The endpoint detector (control/endpoint.py) rule by rule, on hand-made trend samples: the
settings' edges and messages, each criterion at its exact edge (binary-exact MI values), the
dwell window's first sample, what each status carries, the exit rule, and the offline replays."""

from __future__ import annotations

import math

import numpy as np
import pytest

from control.endpoint import (
    EndpointConfig,
    EndpointDetector,
    EndpointStatus,
    block_sd,
    detect_endpoint,
    endpoint_of_series,
    endpoint_settings,
)
from control.errors import ControlError
from control.trend import TrendConfig

# binary-exact MI values: a criterion's edge is reached exactly, not within a rounding
BAND = 0.03125
EXACT = EndpointConfig(target_mi=0.75, band=BAND, dwell_s=10.0, block_sd_max=None, exit_band=0.0625,
                       exit_dwell_s=5.0)


def feed(det: EndpointDetector, levels: list[tuple[float, float]], settled: bool = True) -> list[EndpointStatus]:
    """(t, level) samples, raw MI = the level."""
    return [det.update(t, lv, lv, settled) for t, lv in levels]


def test_the_settings_edges_and_messages() -> None:
    for ok in (dict(target_mi=0.0), dict(target_mi=1.0), dict(band=0.5), dict(dwell_s=3600.0),
               dict(block_sd_max=1.0), dict(exit_dwell_s=0.0)):
        EndpointConfig(**ok)  # type: ignore[arg-type]
    with pytest.raises(ControlError) as e:
        EndpointConfig(band=0.0)
    assert str(e.value) == "endpoint band must be in (0, 0.5], got 0.0"
    with pytest.raises(ControlError) as e:
        EndpointConfig(exit_dwell_s=-1.0)
    assert str(e.value) == "endpoint exit_dwell_s must be in [0, 3600], got -1.0"
    with pytest.raises(ControlError) as e:
        EndpointConfig(dwell_s=math.nan)
    assert str(e.value) == "endpoint settings must be finite numbers (target_mi, band, dwell_s, block_s, ...)"


def test_a_settings_table_turns_the_block_criterion_off_with_none_false_or_0_only() -> None:
    for off in (None, False, 0, 0.0):
        assert endpoint_settings({"block_sd_max": off}).block_sd_max is None
    with pytest.raises(ControlError) as e:
        endpoint_settings({"block_sd_max": True})
    assert str(e.value) == "endpoint block_sd_max must be a number, got True"
    with pytest.raises(ControlError) as e:
        endpoint_settings({"dwell": 3})
    assert str(e.value) == ("endpoint: unknown key(s) ['dwell'] (allowed: target_mi, band, dwell_s, block_s, "
                            "block_sd_max, exit_band, exit_dwell_s)")


def test_a_fresh_detector_says_not_mixed_with_no_time_no_plateau_and_no_reason() -> None:
    st = EndpointDetector(EXACT).update(0.0, 0.8, 0.8)
    assert (st.t_s, st.mixed, st.mixing_time_s, st.plateau_mi, st.changed, st.reason) == (0.0, False, None, None,
                                                                                          "", "")
    assert st.mixed is False and math.isnan(st.block_sd)  # one raw sample: no sd yet


def test_the_window_starts_at_the_sample_exactly_dwell_s_old() -> None:
    det = EndpointDetector(EXACT)
    sts = feed(det, [(0.0, 0.5)] + [(0.5 * k, 0.875) for k in range(1, 22)])
    changed = [(s.t_s, s.mixing_time_s) for s in sts if s.changed]
    assert changed == [(10.5, 0.5)]  # at 10.5 s the 0.5 s sample is exactly 10 s old: the 0 s one is dropped


def test_a_window_short_of_dwell_s_by_a_rounding_is_full() -> None:
    det = EndpointDetector(EXACT)
    t = 11.999999999  # t - dwell_s + 1e-9 is exactly the first sample's 2.0 s
    sts = feed(det, [(2.0, 0.875), (t, 0.875)])
    assert sts[-1].changed == "mixed" and sts[-1].mixing_time_s == t - 10.0


def test_each_plateau_criterion_holds_at_its_exact_edge() -> None:
    def mixed(levels: list[float], config: EndpointConfig = EXACT) -> bool:
        det = EndpointDetector(config)
        return feed(det, [(float(k), lv) for k, lv in enumerate(levels)])[-1].changed == "mixed"

    flat = [0.875] * 11
    assert mixed([0.875] * 5 + [0.9375] + [0.875] * 5)  # max - min = 2 band exactly
    assert not mixed([0.875] * 5 + [0.96875] + [0.875] * 5)  # 3 band: one frame off the band is enough
    assert mixed([0.875] * 10 + [0.90625])  # net change = band exactly
    assert mixed(flat, EndpointConfig(**{**EXACT.__dict__, "target_mi": 0.875}))  # the plateau = the target
    # the net change is the mean of the window's last tenth minus that of its first: with 11 samples
    # one sample each (0.9375 - 0.875: too much), with 20 two each (0.90625 - 0.90625: none)
    ends = [0.875, 0.9375]
    assert not mixed(ends + [0.90625] * 7 + ends)
    assert mixed(ends + [0.90625] * 16 + ends, EndpointConfig(**{**EXACT.__dict__, "dwell_s": 19.0}))


def test_the_block_sd_passes_at_exactly_its_limit_and_counts_samples_exactly_block_s_old() -> None:
    raws = [0.875, 0.9375, 0.875, 0.8125]
    limit = block_sd(raws)
    assert 0 < limit <= 1
    det = EndpointDetector(EndpointConfig(target_mi=0.75, band=BAND, dwell_s=3.0, block_s=3.0, block_sd_max=limit))
    sts = [det.update(float(k), raw, 0.875) for k, raw in enumerate(raws)]
    assert sts[-1].changed == "mixed" and sts[-1].block_sd == limit  # the 0 s raw is 3 s old at 3 s: in the block
    assert sts[-1].reason == f"trend within +-{BAND:g} of 0.875 (>= target 0.75) for 3 s; block sd {limit:.4f} <= " \
                             f"{limit:g} over 3 s"


def test_samples_at_the_same_time_both_count_and_a_nan_time_changes_nothing() -> None:
    det = EndpointDetector(EXACT)
    det.update(1.0, 0.5, 0.875)
    assert det.update(1.0, 0.75, 0.875).block_sd == pytest.approx(1.482602218505602 * 0.125)
    past = det.update(math.nan, 0.25, 0.875)
    assert past.t_s != past.t_s and math.isnan(past.block_sd) and not past.mixed  # nothing read, nothing changed
    old = det.update(0.5, 0.25, 0.875)  # from the past still, after the NaN time
    assert old.t_s == 0.5 and math.isnan(old.block_sd)
    assert det.update(1.5, 0.75, 0.875).block_sd == block_sd([0.5, 0.75, 0.75])


def test_every_status_carries_its_time_and_block_sd() -> None:
    det = EndpointDetector(EXACT)
    sts = feed(det, [(0.0, 0.875), (1.0, 0.8125)])  # not yet: the window is short
    assert (sts[-1].t_s, sts[-1].block_sd) == (1.0, block_sd([0.875, 0.8125]))
    det = EndpointDetector(EXACT)
    sts = feed(det, [(float(k), 0.875) for k in range(10)] + [(10.0, 0.5)])  # a full window, not flat
    assert (sts[-1].t_s, sts[-1].changed, sts[-1].block_sd) == (10.0, "", 0.0)
    sd_det = EndpointDetector(EndpointConfig(**{**EXACT.__dict__, "block_sd_max": 0.01}))
    sts = [sd_det.update(float(k), 0.875 + 0.0625 * (k % 2), 0.875) for k in range(12)]  # flat trend, noisy raw
    assert not any(s.mixed for s in sts) and sts[-1].t_s == 11.0
    assert sts[-1].block_sd == block_sd([0.875 + 0.0625 * (k % 2) for k in range(6, 12)])  # the last 5 s


def test_once_mixed_the_status_carries_the_plateau_and_an_invalid_trend_is_no_evidence() -> None:
    det = EndpointDetector(EXACT)
    sts = feed(det, [(float(k), 0.875) for k in range(11)])
    assert (sts[-1].changed, sts[-1].mixing_time_s, sts[-1].plateau_mi, sts[-1].block_sd) == ("mixed", 0.0, 0.875,
                                                                                              0.0)
    assert sts[-1].reason == "trend within +-0.03125 of 0.875 (>= target 0.75) for 10 s"
    for t in map(float, range(11, 31)):  # unsettled at a low level for longer than exit_dwell_s: no evidence
        st = det.update(t, 0.875, 0.25, settled=False)
        assert (st.t_s, st.mixed, st.plateau_mi, st.block_sd) == (t, True, 0.875, 0.0)
    st = det.update(31.0, 0.875, 0.875)
    assert (st.t_s, st.mixed, st.block_sd, st.reason) == (31.0, True, 0.0, "")


def test_the_exit_floor_is_the_target_minus_band_when_that_is_higher() -> None:
    config = EndpointConfig(target_mi=0.85, band=0.02, dwell_s=10.0, block_sd_max=None, exit_band=0.05,
                            exit_dwell_s=5.0)
    det = EndpointDetector(config)
    feed(det, [(float(k), 0.90) for k in range(11)])
    assert det.mixed and det.plateau_mi == 0.90
    assert not any(s.changed for s in feed(det, [(11.0 + k, 0.86) for k in range(20)]))  # floor 0.85 (not 0.87)
    assert det.mixed


def test_unmixed_after_exactly_exit_dwell_s_below_the_floor_with_its_reason() -> None:
    det = EndpointDetector(EXACT)  # plateau 0.875, exit band 0.0625: floor 0.8125
    feed(det, [(float(k), 0.875) for k in range(11)])
    sts = feed(det, [(11.0 + k, 0.8125) for k in range(10)])  # at the floor: not below it
    assert det.mixed and not any(s.changed for s in sts)
    sts = feed(det, [(21.0 + 0.5 * k, 0.75) for k in range(11)])  # below from 21 s
    assert [(s.t_s, s.changed) for s in sts if s.changed] == [(26.0, "unmixed")]
    waiting = sts[4]  # 23 s: below the floor for 2 s, not yet exit_dwell_s
    assert (waiting.t_s, waiting.mixed, waiting.changed, waiting.block_sd) == (23.0, True, "", 0.0)
    st = next(s for s in sts if s.changed)
    assert st.reason == "trend 0.750 < 0.812 (plateau 0.875 - 0.0625) for 5.0 s"
    assert (st.mixed, st.mixing_time_s, st.plateau_mi, st.block_sd) == (False, None, None, 0.0)


def test_reset_forgets_the_batch_and_its_clock() -> None:
    det = EndpointDetector(EXACT)
    feed(det, [(float(k), 0.875) for k in range(11)])
    assert det.mixed
    det.reset()
    assert (det.mixed, det.mixing_time_s, det.plateau_mi) == (False, None, None)
    st = det.update(0.0, 0.875, 0.875)  # time starts again: 0 s is news, not the past
    assert (st.t_s, st.mixed) == (0.0, False) and math.isnan(st.block_sd)  # the old raw block is gone too
    assert [s.changed for s in feed(det, [(float(k), 0.875) for k in range(1, 11)])][-1] == "mixed"


def test_the_replays_hand_the_settled_flag_on_and_use_the_given_trend() -> None:
    samples = [(float(k), 0.875, 0.875, False) for k in range(30)]
    assert detect_endpoint(samples, EXACT).changes == ()  # never settled: never mixed
    t = np.arange(0.0, 60.0, 0.1)
    flat = np.full(t.size, 0.9)
    assert endpoint_of_series(t, flat).mixing_time_s == 1.0  # the trend settles after settle_s = 1 s of data
    assert endpoint_of_series(t, flat, trend=TrendConfig(settle_s=20.0)).mixing_time_s == 20.0
    with pytest.raises(ValueError):
        endpoint_of_series(t, flat[:-1])


def test_the_replay_takes_the_drum_speed_for_the_trends_ripple() -> None:
    """A ripple at the rotation frequency (20 rpm: 1/3 Hz): with the rpm the trend models it and
    its plateau is the mean; without it the ripple leaks into the level."""
    t = np.arange(0.0, 60.0, 0.1)
    mi = 0.9 + 0.03 * np.sin(2 * math.pi * (20.0 / 60.0) * t)
    config = EndpointConfig(block_sd_max=None)
    known = endpoint_of_series(t, mi, config, rpm=20.0).plateau_mi
    unknown = endpoint_of_series(t, mi, config).plateau_mi
    assert known is not None and unknown is not None
    assert abs(known - 0.9) < 0.005 < abs(unknown - 0.9)
