"""The Kalman trend without scipy: ``control.trend.kalman_filter_class`` is filterpy's own
``KalmanFilter`` loaded without its packages' imports (``scipy.stats`` and ``scipy.linalg``:
~60 MB of the live run's resident memory, issue 26 item 12)."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import numpy as np

from control.trend import MITrend, TrendConfig


def _in_fresh_python(code: str) -> str:
    p = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr[-2000:]
    return p.stdout.strip()


def test_the_trend_imports_no_scipy_and_leaves_no_stand_in_behind() -> None:
    """It imported ``filterpy.kalman`` (every filter, ``scipy.stats``, ``scipy.linalg``)."""
    out = _in_fresh_python("""
        import sys
        from control.trend import MITrend
        t = MITrend()
        for i in range(40):
            t.update(0.1 * i, 0.5 + 0.01 * (i % 3), 10.0)
        print(sorted(k for k in sys.modules if k.split('.')[0] in ('scipy', 'filterpy')))
        import filterpy.stats, filterpy.common  # the real ones still import afterwards
        print(hasattr(filterpy.stats, 'multivariate_normal'), hasattr(filterpy.common, 'Q_discrete_white_noise'))
        print(t.kf.log_likelihood < 0 or t.kf.log_likelihood >= 0)  # logpdf: the real one, imported on use
    """)
    mods, real, ll = out.splitlines()
    assert mods == "[]"
    assert real == "True True" and ll == "True"


def test_the_class_is_filterpys_and_gives_the_same_trend(monkeypatch) -> None:
    """The same numbers as with ``filterpy.kalman.KalmanFilter`` on a noisy step with gaps."""
    import filterpy.kalman

    import control.trend as trend

    rng = np.random.default_rng(3)
    t = np.arange(0, 60, 0.1)
    mi = np.where(t < 30, 0.8, 0.93) + rng.normal(0, 0.02, t.size)
    mi[100:120] = np.nan

    def levels() -> list[tuple[float, float]]:
        tr = MITrend(TrendConfig())
        return [(e.level, e.hi95) for e in (tr.update(float(a), float(b), 20.0) for a, b in zip(t, mi, strict=True))]

    assert trend.kalman_filter_class() is not filterpy.kalman.KalmanFilter  # the private copy: compared
    assert trend.kalman_filter_class().__qualname__ == "KalmanFilter"
    ours = levels()
    monkeypatch.setattr(trend, "kalman_filter_class", lambda: filterpy.kalman.KalmanFilter)
    assert levels() == ours
