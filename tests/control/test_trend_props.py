"""Property tests of the trend: for any sequence of MI (NaN, outliers, values beyond
[0, 1], gaps, rpm changes) the level and its band stay in [0, 1] and the rate in its bound."""

from __future__ import annotations

import math

from hypothesis import given, settings
from hypothesis import strategies as st

from control.trend import MITrend, TrendConfig

mi_values = st.one_of(
    st.floats(0.0, 1.0),
    st.just(math.nan),
    st.floats(-5.0, 5.0),  # outliers, even outside what a meter reports
    st.sampled_from([0.0, 1.0, 0.38, 0.97]),
)
steps = st.lists(
    st.tuples(
        st.one_of(st.just(1 / 30), st.floats(0.0, 0.2), st.floats(0.0, 40.0)),  # frame, jitter, gap
        mi_values,
        st.one_of(st.just(5.0), st.floats(0.0, 60.0), st.just(math.nan)),
    ),
    min_size=1,
    max_size=300,
)


@settings(max_examples=150, deadline=None)
@given(steps)
def test_level_band_and_rate_stay_in_their_ranges(seq):
    tr = MITrend()
    m = tr.config.max_rate_per_s
    t = 0.0
    for dt, mi, rpm in seq:
        t += dt
        e = tr.update(t, mi, rpm)
        if not e.valid:
            continue
        assert 0.0 <= e.lo95 <= e.level <= e.hi95 <= 1.0
        assert abs(e.rate) <= m + 1e-12
        assert math.isfinite(e.level_sd) and e.level_sd >= 0.0
        assert tr.config.min_meas_sd - 1e-12 <= e.meas_sd <= 0.5
        c = tr.config
        assert not e.settled or (e.hi95 - e.lo95 <= c.settle_band_max and e.n_since_init >= c.reinit_min
                                 and tr.accepted_s >= c.settle_s)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(0.0, 1.0), min_size=60, max_size=200), st.floats(0.05, 2.0))
def test_any_rate_bound_holds(values, max_rate):
    tr = MITrend(TrendConfig(max_rate_per_s=max_rate))
    for i, v in enumerate(values):
        e = tr.update(i / 30, v, 10.0)
        assert abs(e.rate) <= max_rate + 1e-12 and 0.0 <= e.level <= 1.0
