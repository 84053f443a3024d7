"""``drumtwin report``'s memory is bounded by the page, not the logs (issue 42, item 4): rows are
decimated as they stream (min/max per bucket: every spike kept), runs are read one at a time, a
report of many runs shows a table row per run and a bounded number of plots; labels split at the
last ``=``; the bench command that measures it prints its numbers (the numbers themselves are in
docs/numbers.md, never asserted)."""

from __future__ import annotations

import gc
import json
import weakref
from pathlib import Path

import numpy as np
import pytest

from tests.cli import assert_one_line_error, cli
from twin.records import FRAME_COLUMNS
from twin.report import build, load_run, render_html, run_specs
from twin.report.bench import write_run
from twin.report.decimate import BUCKETS, MinMax, minmax_rows
from twin.report.frames import PLOTTED
from twin.runlog import RunLog


def test_minmax_keeps_each_buckets_extremes_as_a_brute_force_does() -> None:
    rng = np.random.default_rng(7)
    rows = np.sort(rng.choice(10_000, 3_000, replace=False))
    y = rng.normal(0, 1, rows.size)
    y[rng.random(rows.size) < 0.2] = np.nan
    for width in (1, 7, 64, 1000):
        keep = minmax_rows(rows, y, width)
        for b in np.unique(rows // width):
            sel = rows // width == b
            kept = keep[np.isin(keep, np.flatnonzero(sel))]
            if np.isnan(y[sel]).all():
                assert len(kept) == 1 and np.isnan(y[kept[0]])  # the gap kept, once
            else:
                assert np.nanmin(y[kept]) == np.nanmin(y[sel]) and np.nanmax(y[kept]) == np.nanmax(y[sel])
                assert len(kept) <= 2


def test_streamed_decimation_is_bounded_and_keeps_every_spike() -> None:
    rng = np.random.default_rng(1)
    n = 300_000
    y = rng.normal(0.9, 0.01, n)
    spikes = [1234, 150_001, 299_998]
    y[spikes] = [0.1, 1.7, -3.0]
    y[50_000:52_000] = np.nan  # invalid frames: a gap
    t = np.arange(n) / 10.0
    m, i = MinMax(), 0
    while i < n:  # batches of uneven size, as blocks of a file give them
        k = int(rng.integers(1, 9000))
        m.add(t[i:i + k], y[i:i + k])
        i += k
    x, v = m.points()
    assert len(x) <= 4 * BUCKETS + 2 * 9000 and np.all(np.diff(x) > 0)
    for s in spikes:
        assert t[s] in x and v[np.flatnonzero(x == t[s])[0]] == y[s]
    assert np.isnan(v[(x >= 5000) & (x < 5200)]).any()  # the gap is drawn as one


def test_a_long_log_is_read_into_a_few_thousand_points(tmp_path: Path) -> None:
    """40,000 rows (the bench's generator: a one-frame MI spike every 5,000 rows): every plotted
    series is at most ~4 points a bucket, the spikes are in it, the counts are the log's."""
    d = write_run(tmp_path / "long", 40_000)
    run = load_run(d)
    assert run.n_frames == 40_000 and run.notes == [] and run.frames.t_max == pytest.approx(3999.9)
    for name in PLOTTED:
        t, _ = run.series(name)
        assert 0 < len(t) <= 4 * BUCKETS + 4_000, name
    t, mi = run.series("mi")
    assert np.sum(mi == 0.2) == 8  # rows 4999, 9999, ...: every one-frame dip of the log
    assert run.endpoint["source"] == "live" and run.endpoint["mixing_time_s"] == 80.0
    assert run.time_to_mix is not None and run.time_to_mix["rpm"] == 25.0
    assert run.events.n_moves == 6 and run.events.counts["decision"] == 6


def test_runs_are_read_one_at_a_time_and_many_runs_make_a_bounded_page(tmp_path: Path, monkeypatch) -> None:
    """Five runs, two shown in detail (the command's limit is eight): while the report reads a run,
    no earlier run's data is alive; the page has an "All runs" row for each, every section for
    the first two only, and one overview plot."""
    dirs = [write_run(tmp_path / f"r{i:02d}", 300, seed=i) for i in range(5)]
    alive: list[weakref.ref] = []
    real = build.load_run

    def load(path, label=None):
        gc.collect()
        assert [r for r in alive if r() is not None] == [], "an earlier run is still held"
        run = real(path, label)
        alive.append(weakref.ref(run))
        return run

    monkeypatch.setattr(build, "load_run", load)
    out, results = build.write_report(dirs, tmp_path / "many.html", detailed=2)
    page = out.read_text(encoding="utf-8")
    assert page.count('data-section="summary"') == 2 and len(alive) == 5
    assert 'id="plot-overview-0"' in page and page.count('class="run-label"') == 5  # a row per run
    assert set(results) == {d.name for d in dirs} and all(r["mixing_time_s"] is None for r in results.values())


def test_labels_split_at_the_last_equals_and_a_path_that_exists_is_a_path(tmp_path: Path) -> None:
    with RunLog(tmp_path / "a=b") as log:
        log.frame({"t_s": 0.0, "mi": 0.5})
    d = tmp_path / "a=b"
    assert run_specs([str(d)]) == [("a=b", d)]  # exists as given: a path, its folder name the label
    assert run_specs([f"my=label={tmp_path / 'x'}"]) == [("my=label", tmp_path / "x")]  # the last '='
    assert run_specs([f"={tmp_path / 'x'}"]) == [("x", tmp_path / "x")]  # no label: the folder's name
    assert run_specs([str(d)], ["A"]) == [("A", d)]
    out = tmp_path / "r.html"
    r = cli("report", f"lab=el={tmp_path}/a=b", "--out", out)  # the last '=' splits "b" off: no such dir
    assert_one_line_error(r, "no such run dir")
    for args in ((d,), (d, "--label", "L=1")):
        r = cli("report", *args, "--out", out, "--json")
        assert r.code == 0, r.err
        assert list(json.loads(r.out)) == [args[-1] if len(args) > 1 else "a=b"]
    c = cli("compare", d, "--label", "first=run", "--plot", tmp_path / "c.png")
    assert c.code == 0 and "first=run" in c.out, c.err
    assert_one_line_error(cli("report", d, d, "--label", "A", "--out", out), "--label given 1 time(s) for 2 run(s)")
    assert_one_line_error(cli("compare", d, "--label", " ", "--plot", tmp_path / "c.png"), "cannot be empty")


def test_a_log_without_the_endpoint_column_is_replayed_offline(tmp_path: Path) -> None:
    """A log of a release before the endpoint (no mixed column, no events): the detector runs
    on its raw MI, and the report says so."""
    cols = tuple(c for c in FRAME_COLUMNS if c not in ("mixed", "mixing_time_s"))
    t = np.arange(0.0, 120.0, 0.1)
    mi = np.clip(0.95 - 0.5 * np.exp(-t / 15.0) + np.random.default_rng(0).normal(0, 0.005, t.size), 0, 1)
    with RunLog(tmp_path / "old", columns=cols) as log:
        for ti, m in zip(t, mi, strict=True):
            log.frame({"t_s": ti, "mi": m})
    run = load_run(tmp_path / "old")
    assert run.endpoint["source"].startswith("offline")
    assert run.endpoint["mixing_time_s"] is not None and 20 < run.endpoint["mixing_time_s"] < 100


def test_the_plots_place_the_largest_numbers_a_log_may_keep(tmp_path: Path) -> None:
    """Values at the report's limit (±1e15: anything beyond is skipped) still draw (matplotlib's
    axis math fails on 1e308, not here)."""
    with RunLog(tmp_path / "edge") as log:
        log.frame({"t_s": -1e15, "mi": 1e15, "rpm_actual": -1e15, "slope_deg": 0.0})
        log.frame({"t_s": 1e15, "mi": -1e15, "rpm_actual": 1e15, "twin_slope_deg": 1e15})
    page = render_html([load_run(tmp_path / "edge")])
    assert page.count("data:image/png;base64,") >= 4


def test_bench_report_prints_wall_time_and_peak_memory() -> None:
    r = cli("bench", "report", "--rows", "300", "--runs", "2", "--json")
    assert r.code == 0, r.err
    res = json.loads(r.out)
    assert res["rows"] == 300 and res["runs"] == 2 and res["exit_code"] == 0
    assert res["wall_s"] > 0 and res["peak_rss_mb"] > 30 and res["html_mb"] > 0 and res["logs_mb"] > 0
