"""``report`` and ``compare`` by run id and by the catalogue's filters (issue 40), and a
multi-run report's batch table: mixing time and energy per run, mean and sd per rpm profile,
each run against its rig's golden batch. The run folders are written by the real ``RunLog``."""

from __future__ import annotations

import json
import statistics
import time
from html.parser import HTMLParser
from pathlib import Path

import pytest

from tests.catalogue_runs import RunSpec, make_run, stamp
from tests.cli import assert_one_line_error, cli
from twin.catalogue.summary import RunSummary
from twin.report.batch import against, groups, mean_sd

DAY = 86400.0


class Tables(HTMLParser):
    """The cells' text of each ``<table class=...>`` of a page."""

    def __init__(self) -> None:
        super().__init__()
        self.tables: dict[str, list[list[str]]] = {}
        self._rows: list[list[str]] | None = None
        self._cell: list[str] | None = None

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        if tag == "table":
            self._rows = self.tables.setdefault(dict(attrs).get("class") or "", [])
        elif tag == "tr" and self._rows is not None:
            self._rows.append([])
        elif tag in ("td", "th"):
            self._cell = []

    def handle_endtag(self, tag: str) -> None:
        if tag in ("td", "th") and self._cell is not None and self._rows is not None:
            self._rows[-1].append(" ".join("".join(self._cell).split()))
            self._cell = None
        elif tag == "table":
            self._rows = None

    def handle_data(self, data: str) -> None:
        if self._cell is not None:
            self._cell.append(data)


def tables(page: Path) -> dict[str, list[list[str]]]:
    p = Tables()
    p.feed(page.read_text(encoding="utf-8"))
    return p.tables


# mixing time s, energy J, rpm moves: r2 and r3 share the 5 -> 20 rpm profile
SPECS = {
    "r0": RunSpec(mixing_time_s=31.0, energy_j=100.0, rpms=(20.0,)),  # the golden batch, older than --last 3
    "r1": RunSpec(mixing_time_s=44.0, energy_j=130.0, rpms=(20.0,)),
    "r2": RunSpec(mixing_time_s=36.5, energy_j=112.0, rpms=(12.0, 20.0)),
    "r3": RunSpec(mixing_time_s=47.0, energy_j=121.0, rpms=(20.0,)),
    "r4": RunSpec(mixing_time_s=22.0, energy_j=240.0, rpms=(40.0,)),
    "g0": RunSpec(rig="glass", mixing_time_s=10.0, energy_j=50.0),  # another rig, newest of all
}


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("catalogue") / "runs"
    t0 = time.time() - 30 * DAY
    for i, (name, spec) in enumerate(SPECS.items()):
        stamp(make_run(root / name, spec), t0 + i * DAY)
    rows = json.loads(cli("runs", "list", "--runs-dir", root, "--json").out)
    golden = next(r["id"] for r in rows if r["path"].endswith("/r0"))
    assert cli("runs", "golden", golden[:8], "--runs-dir", root).code == 0
    return root


def test_report_of_a_rigs_last_three_runs_renders_the_batch_table_against_its_golden_batch(runs, tmp_path) -> None:
    out = tmp_path / "r.html"
    r = cli("report", "--rig", "pmma", "--last", "3", "--runs-dir", runs, "--out", out, "--json")
    assert r.code == 0, r.err
    assert list(json.loads(r.out)) == ["r4", "r3", "r2"]  # the rig's newest three, newest first
    t = tables(out)
    head, *rows = t["batch-runs"]
    col = {name: i for i, name in enumerate(head)}
    assert [row[col["run"]] for row in rows] == ["r4", "r3", "r2"]  # no golden mark: r0 is not among them
    gold = SPECS["r0"]
    for row in rows:
        spec = SPECS[row[col["run"]]]
        assert float(row[col["mixing time s"]]) == spec.mixing_time_s
        assert float(row[col["energy J"]]) == spec.energy_j
        assert float(row[col["vs golden: mixing time s"]]) == pytest.approx(spec.mixing_time_s - gold.mixing_time_s)
        assert float(row[col["vs golden: energy J"]]) == pytest.approx(spec.energy_j - gold.energy_j)
    assert [row[col["rpm start→final"]] for row in rows] == ["5→40", "5→20", "5→20"]
    head, *grows = t["batch-groups"]
    assert head == ["rig", "rpm start→final", "runs", "mixed", "mixing time s: mean", "sd", "energy J: mean", "sd"]
    by_profile = {g[1]: g for g in grows}
    assert set(by_profile) == {"5→40", "5→20"}
    pair = [SPECS["r3"], SPECS["r2"]]
    _rig, _prof, n, n_mixed, t_mean, t_sd, e_mean, e_sd = by_profile["5→20"]
    assert (n, n_mixed) == ("2", "2")
    assert float(t_mean) == pytest.approx(statistics.fmean(s.mixing_time_s for s in pair), abs=0.05)
    assert float(t_sd) == pytest.approx(statistics.stdev([s.mixing_time_s for s in pair]), abs=0.05)
    assert float(e_mean) == pytest.approx(statistics.fmean(s.energy_j for s in pair), abs=0.05)
    assert float(e_sd) == pytest.approx(statistics.stdev([s.energy_j for s in pair]), abs=0.05)
    assert by_profile["5→40"][5] == "–" and by_profile["5→40"][7] == "–"  # one run: no spread
    [golden_row] = t["batch-golden"][1:]
    assert golden_row[0] == "pmma" and golden_row[1].endswith("r0")
    assert float(golden_row[4]) == gold.mixing_time_s and float(golden_row[5]) == gold.energy_j
    page = out.read_text(encoding="utf-8")
    assert page.count('data-section="summary"') == 3 and "g0" not in json.loads(r.out)


def test_the_golden_batch_in_the_report_is_marked_and_a_rig_without_one_says_so(runs, tmp_path) -> None:
    out = tmp_path / "r.html"
    r = cli("report", "r0", "g0", "--runs-dir", runs, "--out", out)  # folder names, looked up
    assert r.code == 0, r.err
    rows = tables(out)["batch-runs"][1:]
    assert rows[0][0] == "r0 golden" and rows[0][8] == "+0.0"
    assert rows[1][0] == "g0" and rows[1][8] == "–"  # glass has no golden batch
    assert "No golden batch for rig glass" in out.read_text(encoding="utf-8")


def _compared(c) -> list[str]:
    """The run labels of ``compare``'s table, in order."""
    assert c.code == 0, c.err
    return [ln.split("│")[1].strip() for ln in c.out.splitlines() if ln.startswith("│")]


def test_report_and_compare_take_ids_prefixes_folder_names_labels_and_filters(runs, tmp_path) -> None:
    ids = {Path(r["path"]).name: r["id"] for r in json.loads(cli("runs", "list", "--runs-dir", runs, "--json").out)}
    png = tmp_path / "c.png"
    c = cli("compare", ids["r1"], ids["r2"][:8], "r3", f"mine={ids['r4']}", runs / "r0", "--runs-dir", runs,
            "--plot", png)
    assert _compared(c) == ["r1", "r2", "r3", "mine", "r0"] and png.stat().st_size > 10_000
    c = cli("compare", "r1", "--rig", "pmma", "--mode", "auto", "--last", "2", "--runs-dir", runs, "--plot", png)
    assert _compared(c) == ["r1", "r4", "r3"]  # the arguments, then the filter's runs not given
    r = cli("report", ids["r2"][:6], "--runs-dir", runs, "--out", tmp_path / "r.html", "--json")
    assert r.code == 0 and list(json.loads(r.out)) == ["r2"], r.err


def test_runs_not_found_and_filters_that_match_nothing_are_one_line_errors(runs, tmp_path) -> None:
    out = tmp_path / "r.html"
    assert_one_line_error(cli("report", "nope", "--runs-dir", runs, "--out", out), "no such run dir or run id", "nope")
    assert_one_line_error(cli("report", "--rig", "steel", "--runs-dir", runs, "--out", out), "matches the filter")
    assert_one_line_error(cli("compare", "--rig", "pmma", "--label", "A", "--runs-dir", runs, "--plot",
                              tmp_path / "c.png"), "--label", "filter")
    assert_one_line_error(cli("report", "--runs-dir", runs, "--out", out), "give at least one run")
    assert_one_line_error(cli("report", "--rpm", "fast", "--runs-dir", runs, "--out", out), "--rpm")
    empty = tmp_path / "elsewhere"
    empty.mkdir()
    assert_one_line_error(cli("report", "r1", "--runs-dir", empty, "--out", out), "no run catalogue")
    assert not any(empty.iterdir()) and not out.exists()  # a look-up makes no catalogue
    typo = cli("report", "r1", "--runs-dir", tmp_path / "typo", "--out", out)
    assert_one_line_error(typo, "--runs-dir", "not a folder")


def test_folders_without_a_catalogue_get_the_table_without_golden_batches(runs, tmp_path) -> None:
    out = tmp_path / "r.html"
    (tmp_path / "none").mkdir()  # a folder of runs without a catalogue
    r = cli("report", runs / "r1", runs / "r2", "--runs-dir", tmp_path / "none", "--out", out)
    assert r.code == 0, r.err
    rows = tables(out)["batch-runs"][1:]
    assert [(row[0], row[6], row[8]) for row in rows] == [("r1", "44.0", "–"), ("r2", "36.5", "–")]
    assert "no golden batches: no run catalogue at" in out.read_text(encoding="utf-8")
    r = cli("report", runs / "r1", "--runs-dir", runs, "--out", out)  # one run: no batch table
    assert r.code == 0 and "batch-runs" not in out.read_text(encoding="utf-8")


def _summary(i: int, **kw: object) -> RunSummary:
    return RunSummary(**{"id": f"run{i}", "path": f"/r/{i}", "rig": "pmma", "rig_hash": "h", "started_s": float(i),
                         "mode": "auto", "rpm_start": 5.0, "rpm_final": 20.0, "mixed": True, **kw})  # type: ignore[arg-type]


def test_groups_and_the_golden_difference_leave_out_what_is_unknown() -> None:
    runs = [_summary(0, mixing_time_s=30.0, energy_j=90.0), _summary(1, mixing_time_s=40.0),
            _summary(2, mixed=False, mixing_time_s=99.0, energy_j=110.0),  # left its band: no mixing time
            _summary(3, rpm_final=20.04, mixing_time_s=50.0),  # the same profile to 0.1 rpm
            _summary(4, rpm_start=20.0, mixing_time_s=10.0)]  # 20 -> 20: another recipe
    g5, g20 = groups(runs)
    assert (g5.runs, g5.mixed, g20.runs) == (4, 3, 1)
    assert g5.mixing_time_s == pytest.approx((40.0, 10.0)) and g5.energy_j == pytest.approx((100.0, 14.1421356))
    assert g20.mixing_time_s == (10.0, None) and g20.energy_j == (None, None)
    assert mean_sd([]) == (None, None)
    golden = _summary(9, mixing_time_s=25.0, energy_j=80.0)
    assert against(runs[0], golden) == (5.0, 10.0)
    assert against(runs[1], golden) == (15.0, None)  # no energy logged
    assert against(runs[2], golden) == (None, 30.0)  # not mixed: no time to compare
    assert against(runs[0], None) == (None, None)
    assert against(runs[0], _summary(9, mixed=False, mixing_time_s=25.0)) == (None, None)
