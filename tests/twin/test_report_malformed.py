"""``drumtwin report`` and ``drumtwin compare`` read any log (issue 42, item 4): a sweep of run
folders broken one way each (every file of the folder, its lines, its cells, each plotted
column), made here from one good run written by the real ``RunLog``. Each case: no traceback;
exit 0 and a note on the run that says what was skipped and why (counted); or, where nothing
in the folder is readable, exit 2 and one line.

The notes are checked per case on ``load_run`` (what the report and compare read with); the two
commands then run once each, in-process, over every case together.
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import pytest

from tests.cli import assert_one_line_error, cli
from twin.records import FRAME_COLUMNS, DecisionMade, Mixed, OperatorAction, RunStart, RunStop, WhatIfResult
from twin.report import load_run
from twin.report.frames import PLOTTED
from twin.runlog import RunLog

ROWS = 40


def good_run(d: Path) -> Path:
    """A small AUTO run: 40 frames, a study, a move, the endpoint, a stop."""
    with RunLog(d, columns=(*FRAME_COLUMNS, "power_w")) as log:
        log.set_metadata(config={"mode": "auto", "target_mi": 0.9}, versions={"numpy": "2"})
        log.record(RunStart(t_s=0.0, mode="auto", mill="x"))
        for i in range(ROWS):
            t = i * 0.1
            log.frame(dict(t_s=t, frame=i, mi=0.8 + i / 400, trend_mi=0.8 + i / 400, twin_mi=0.81,
                           rpm_setpoint=5.0 if i < 10 else 25.0, rpm_actual=5.0 if i < 12 else 25.0, slope_deg=30.0,
                           twin_slope_deg=31.0, mode="auto", valid=True, mixed=i >= 30,
                           mixing_time_s=2.5 if i >= 30 else None, power_w=1.0))
        log.record(WhatIfResult(t_s=0.9, reason="AUTO", requested_t_s=0.5, duration_s=2.0,
                                predictions={"5.0": 0.8, "25.0": 0.95}, took_s=0.1, target_mi=0.85,
                                time_to_target_s={"5.0": 9.0, "25.0": 1.0}))
        log.record(DecisionMade(t_s=1.0, decision="move", mode="auto", action="set_rpm", reason="r", rpm=25.0,
                                target_rpm=25.0, safe=False, level=0.8, rate=0.0,
                                predictions={"5.0": 0.8, "25.0": 0.95}, inputs={}))
        log.record(OperatorAction(t_s=1.5, action="start"))
        log.record(Mixed(t_s=3.0, mixing_time_s=2.5, plateau_mi=0.88, reason="r"))
        log.record(RunStop(t_s=3.9, frames=ROWS, workers_alive=(), failure=None))
    return d


def _lines(p: Path) -> list[bytes]:
    return p.read_bytes().splitlines(keepends=True)


def append(name: str, *lines: bytes) -> object:
    def f(d: Path) -> None:
        with open(d / name, "ab") as fh:
            fh.write(b"".join(lines))
    return f


def replace(name: str, data: bytes) -> object:
    def f(d: Path) -> None:
        (d / name).write_bytes(data)
    return f


def remove(name: str) -> object:
    def f(d: Path) -> None:
        (d / name).unlink()
    return f


def set_cell(column: str, value: str, rows: int = 3) -> object:
    """``column`` of the first ``rows`` data rows of frames.csv set to ``value``."""
    def f(d: Path) -> None:
        lines = (d / "frames.csv").read_text(encoding="utf-8").splitlines(keepends=True)
        head = lines[0].rstrip("\n").split(",")
        k = head.index(column)
        for i in range(1, rows + 1):
            cells = lines[i].rstrip("\n").split(",")
            cells[k] = value
            lines[i] = ",".join(cells) + "\n"
        (d / "frames.csv").write_text("".join(lines), encoding="utf-8")
    return f


def uid_of_another_run(name: str) -> object:
    def f(d: Path) -> None:
        p = d / name
        uid = json.loads((d / "metadata.json").read_text())["run_uid"]
        p.write_bytes(p.read_bytes().replace(uid.encode(), b"00000000-0000-4000-8000-000000000000"))
    return f


BIG_CELL = "9" * 140_000  # over the csv module's 131,072-character field limit
NESTED = b"[" * 100_000 + b"]" * 100_000
# (case, how to break the good run, a note the report must show); the plot's hazards first
CASES: list[tuple[str, object, str]] = [
    ("t_inf", set_cell("t_s", "inf"), "3 lines of frames.csv skipped: t_s not a finite number within ±1e+15"),
    ("t_minus_inf", set_cell("t_s", "-inf"), "3 lines of frames.csv skipped: t_s not a finite number"),
    ("t_1e308", set_cell("t_s", "1e308"), "3 lines of frames.csv skipped: t_s not a finite number"),
    ("t_nan", set_cell("t_s", "nan", 1), "1 line of frames.csv skipped: t_s not a finite number"),
    ("t_abc", set_cell("t_s", "abc"), "3 lines of frames.csv skipped: t_s not a number"),
    ("t_empty", set_cell("t_s", ""), "3 lines of frames.csv skipped: t_s empty"),
    *[(f"{c}_{name}", set_cell(c, v), f"3 cells of frames.csv skipped: {c} {why}")
      for c in (*PLOTTED, "power_w", "mixed")
      for name, v, why in (("inf", "inf", "infinite"), ("1e308", "-1e308", "infinite or beyond"),
                           ("abc", "abc", "not a number"))],
    ("big_cell", set_cell("mode", BIG_CELL, 2), "2 lines of frames.csv skipped: longer than 65,536 characters"),
    ("short_row", append("frames.csv", b"1.0,2.0,3\n"), "1 line of frames.csv skipped: wrong number of cells"),
    ("long_row", append("frames.csv", b"1," * 40 + b"\n"), "1 line of frames.csv skipped: wrong number of cells"),
    ("empty_line", append("frames.csv", b"\n"), "1 line of frames.csv skipped: wrong number of cells"),
    ("cut_off_row", append("frames.csv", b"4.0,17000"), "1 line of frames.csv skipped: cut off at the end"),
    ("binary_row", append("frames.csv", b"\xff\xfe\x00\x81garbage\n"), "1 line of frames.csv skipped: not UTF-8"),
    ("quote_row", append("frames.csv", b'4.1,"unclosed\n'), "frames.csv skipped: wrong number of cells"),
    ("cr_in_row", append("frames.csv", b"4.2,1\r2,3\n"), "frames.csv skipped"),
    ("rows_of_another_run", uid_of_another_run("frames.csv"), f"{ROWS} lines of frames.csv skipped: of another run"),
    ("frames_header_only", lambda d: (d / "frames.csv").write_bytes(_lines(d / "frames.csv")[0]),
     "no frame rows were logged"),
    ("frames_empty", replace("frames.csv", b""), "frames.csv not read: empty"),
    ("frames_missing", remove("frames.csv"), "no frames.csv"),
    ("frames_no_t_s", lambda d: (d / "frames.csv").write_bytes(b"a,b\n1,2\n"), "no t_s column in its header"),
    ("frames_binary_header", replace("frames.csv", b"\xff\xd8\xff\xe0garbage\n1,2\n"), "not UTF-8"),
    ("frames_one_huge_line", replace("frames.csv", b"x" * 3_000_000), "first line is longer than"),
    ("frames_random_bytes", replace("frames.csv", os.urandom(200_000).replace(b"\n", b"\r")),
     "frames.csv not read"),
    ("event_5", append("events.jsonl", b"5\n", b"[1, 2]\n", b"null\n", b'"s"\n', b"true\n"),
     "5 lines of events.jsonl skipped: not a JSON object"),
    ("event_t_abc", append("events.jsonl", b'{"kind": "decision", "t_s": "abc"}\n'),
     "1 line of events.jsonl skipped: t_s not a number"),
    ("event_t_inf", append("events.jsonl", b'{"kind": "fault", "t_s": Infinity}\n', b'{"kind": "x", "t_s": NaN}\n',
                           b'{"kind": "x", "t_s": -1e308}\n'),
     "3 lines of events.jsonl skipped: t_s not a finite number within ±1e+15"),
    ("event_t_huge_int", append("events.jsonl", b'{"kind": "fault", "t_s": ' + b"7" * 400 + b"}\n"),
     "1 line of events.jsonl skipped: t_s not a finite number"),
    ("event_no_kind", append("events.jsonl", b'{"t_s": 1.0}\n', b'{"t_s": 1.0, "kind": 5}\n'),
     "2 lines of events.jsonl skipped: no kind"),
    ("event_not_json", append("events.jsonl", b"{not json\n", NESTED + b"\n"),
     "2 lines of events.jsonl skipped: not JSON"),
    ("event_binary", append("events.jsonl", b"\x00\xff\xfe\n"), "1 line of events.jsonl skipped: not UTF-8"),
    ("event_huge", append("events.jsonl", b'{"kind": "x", "t_s": 1, "a": "' + b"y" * 1_100_000 + b'"}\n'),
     "1 line of events.jsonl skipped: longer than 1,048,576 characters"),
    ("event_cut_off", append("events.jsonl", b'{"kind": "stop", "t_s": 4'), "1 line of events.jsonl skipped: cut off"),
    ("event_fields_of_any_type", append("events.jsonl", *[json.dumps(e).encode() + b"\n" for e in (
        {"kind": "decision", "t_s": 1.2, "decision": "move", "target_rpm": "abc", "predictions": 5, "reason": {}},
        {"kind": "decision", "t_s": 1.3, "decision": "move", "target_rpm": 1e300, "predicted_time_to_target_s": 1e300},
        {"kind": "whatif", "t_s": 1.1, "energy_to_target_j": {"a": "b"}, "time_to_target_s": [1, 2],
         "predictions": None},
        {"kind": "mixed", "t_s": 3.5, "mixing_time_s": "x", "plateau_mi": [1]},
        {"kind": "unmixed", "t_s": 1e14, "reason": None},
        {"kind": "decision", "t_s": 1.4, "decision": "move", "target_rpm": 7 * 10**400, "rpm": -(10**401)},
        {"kind": "whatif", "t_s": 1.5, "energy_to_target_j": {"5": 10**400}, "time_to_target_s": {"5": 10**400},
         "target_mi": 10**400, "duration_s": 10**400},
        {"kind": "mixed", "t_s": 3.6, "mixing_time_s": 10**400, "plateau_mi": 10**400})]), ""),
    ("events_of_another_run", uid_of_another_run("events.jsonl"), "6 lines of events.jsonl skipped: of another run"),
    ("events_empty", replace("events.jsonl", b""), "did not end cleanly"),
    ("events_missing", remove("events.jsonl"), "no events.jsonl"),
    ("events_a_directory", lambda d: ((d / "events.jsonl").unlink(), (d / "events.jsonl").mkdir()),
     "no events.jsonl"),
    *[(f"metadata_{n}", replace("metadata.json", v), f"metadata.json not read: {why}") for n, v, why in (
        ("5", b"5", "not a JSON object"), ("list", b"[1]", "not a JSON object"), ("null", b"null", "not a JSON object"),
        ("empty", b"", "empty"), ("broken", b'{"config": ', "not JSON"), ("binary", b"\xff\xfe\x00", "not UTF-8"),
        ("nested", NESTED, "not JSON"))],
    ("metadata_fields_of_any_type", replace("metadata.json", b'{"config": 5, "versions": [1], "run_uid": 7}'), ""),
    ("metadata_missing", remove("metadata.json"), "no metadata.json"),
    ("metadata_of_another_run", uid_of_another_run("metadata.json"), "metadata.json not used: of another run"),
]


@pytest.fixture(scope="module")
def folders(tmp_path_factory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("malformed")
    base = good_run(root / "good")
    out = {}
    for name, breaks, _ in CASES:
        d = root / name
        shutil.copytree(base, d)
        breaks(d)  # type: ignore[operator]
        out[name] = d
    return out


@pytest.mark.parametrize("name", [c[0] for c in CASES])
def test_each_broken_log_reads_with_a_note_saying_what_was_skipped(folders, name) -> None:
    note = next(n for c, _, n in CASES if c == name)
    run = load_run(folders[name])
    if note:
        assert any(note in n for n in run.notes), (note, run.notes)
    else:  # fields of any type in lines that are events: nothing to skip
        assert run.notes == []
    if name.startswith(("event", "metadata")):  # the frames are untouched: all there
        assert run.n_frames == ROWS, run.notes


def test_report_and_compare_of_every_broken_log_exit_0_without_a_traceback(folders, tmp_path) -> None:
    dirs = [folders[c[0]] for c in CASES]
    r = cli("report", *dirs, "--out", tmp_path / "r.html")
    assert r.code == 0 and "Traceback" not in r.err + r.out, r.err[-3000:]
    page = (tmp_path / "r.html").read_text(encoding="utf-8")
    assert page.count('class="run-label"') == len(CASES)  # the all-runs table: a row per run
    for name, _, note in CASES:
        assert note.replace("'", "&#x27;") in page, (name, note)
    c = cli("compare", *dirs, "--plot", tmp_path / "c.png")
    assert c.code == 0 and "Traceback" not in c.err + c.out, c.err[-3000:]
    assert (tmp_path / "c.png").stat().st_size > 10_000
    for name, _, note in CASES:
        if note:
            assert f"note: {name}: " in c.err and note in c.err, (name, note)


NOTHING = {
    "all_empty": {"frames.csv": b"", "events.jsonl": b"", "metadata.json": b""},
    "all_garbage": {"frames.csv": b"\xff\x00garbage", "events.jsonl": b"\x81\n5\n", "metadata.json": b"[]"},
    "only_bad_events": {"events.jsonl": b"null\n[1]\n"},
}


@pytest.mark.parametrize("name", sorted(NOTHING))
def test_a_run_dir_with_nothing_readable_is_one_line_exit_2(tmp_path, name) -> None:
    d = tmp_path / name
    d.mkdir()
    for f, data in NOTHING[name].items():
        (d / f).write_bytes(data)
    assert_one_line_error(cli("report", d, "--out", tmp_path / "r.html"), "nothing readable", name)
    assert_one_line_error(cli("compare", d, "--plot", tmp_path / "c.png"), "nothing readable", name)
    assert not (tmp_path / "r.html").exists() and not (tmp_path / "c.png").exists()
    (d / "junk.txt").write_text("x")
    for f in NOTHING[name]:
        (d / f).unlink()
    assert_one_line_error(cli("report", d, "--out", tmp_path / "r.html"), "not a run log dir")
