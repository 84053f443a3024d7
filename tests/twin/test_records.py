"""The run's typed records (twin/records.py): one definition of the CSV schema, of every event
kind and of the active faults; one frame traced from the process worker to the CSV row, the
JSONL and the dashboard's state; the docs table generated from the code."""

from __future__ import annotations

import ast
import logging
import math
import queue
import sys
from dataclasses import fields
from pathlib import Path

import pytest

from control.trend import MITrend
from tests.twin.workers_fakes import Boxes, reading
from twin.live.camera import CameraReading, ProcessWorker
from twin.live.events import RunEvents
from twin.records import (
    FRAME_COLUMNS,
    KINDS,
    SERIES,
    ActiveFaults,
    DecisionMade,
    FaultCleared,
    FaultRaised,
    FrameReading,
    Mixed,
    OperatorAction,
    TrendUnsettled,
    Unmixed,
    UntypedEvent,
    event_fields,
    record_of,
    records_table,
)
from twin.runlog import RunLog, read_events, read_frames, read_records, to_jsonable
from twin.state import LiveState

ROOT = Path(__file__).resolve().parents[2]
TWIN = ROOT / "twin"


def _modules(*roots: Path) -> list[tuple[Path, ast.Module]]:
    """Every module under ``roots`` (default twin/), parsed."""
    return [(p, ast.parse(p.read_text(encoding="utf-8"))) for r in (roots or (TWIN,)) for p in sorted(r.rglob("*.py"))]


def test_the_docs_list_every_record_kind_with_its_fields_and_units() -> None:
    """docs/architecture.md carries the table ``twin.records.records_table()`` makes from the
    classes (regenerate it with ``python -m twin.records``): a kind or field added, renamed or
    given another unit without the docs fails here."""
    text = (ROOT / "docs" / "architecture.md").read_text(encoding="utf-8")
    begin, end = "<!-- records:begin -->\n", "<!-- records:end -->"
    assert begin in text and end in text
    assert text.split(begin, 1)[1].split(end, 1)[0] == records_table()
    for kind, cls in KINDS.items():
        assert f"| `{kind}` |" in records_table()
        assert all(f.metadata.get("unit") is not None for f in fields(cls)), kind


SINK_METHODS = {"publish", "metadata"}
"""What ``twin.live.events.EventSink`` offers: typed records and the run's metadata."""


def _calls(tree: ast.Module) -> list[ast.Call]:
    return [n for n in ast.walk(tree) if isinstance(n, ast.Call)]


def test_every_producer_constructs_its_record_no_kind_is_named_by_string() -> None:
    """Issue 25: every worker, the loop and the dashboard publish a record they construct
    (``MillRefused(t_s=..., reason=...)``), so mypy catches a misspelt kind or field. In twin/
    no call passes a string kind (``.event("mill_refused", ...)``, ``record_of("...")`` outside
    the JSONL reader), no ``.fault``/``.clear_fault`` by key, and no record is built from a
    spread dict (``**st.as_dict()``). The old code had each of these (mill worker, relearn,
    dashboard, ``RunEvents.fault``); a new one fails here."""
    import inspect

    from twin.live.events import EventSink

    record_classes = {cls.__name__ for cls in KINDS.values()} | {"MillRefusedRecord", "MillMismatchRecord", "change"}
    bad, built = [], 0
    for path, tree in _modules():
        where = str(path.relative_to(ROOT))
        for node in _calls(tree):
            name = node.func.attr if isinstance(node.func, ast.Attribute) else getattr(node.func, "id", "")
            first = node.args[0] if node.args else None
            by_name = name in ("event", "_event", "publish", "publish_throttled", "on_error")
            if by_name and isinstance(first, ast.Constant) and isinstance(first.value, str):
                bad.append((where, node.lineno, f"{name}({first.value!r})"))
            if name in ("fault", "clear_fault") and isinstance(node.func, ast.Attribute):
                bad.append((where, node.lineno, name))
            if name == "record_of" and where not in ("twin/records.py", "twin/runlog.py"):
                bad.append((where, node.lineno, "record_of"))
            if name in record_classes:
                built += 1
                if any(k.arg is None for k in node.keywords):
                    bad.append((where, node.lineno, f"{name}(**...)"))
    assert bad == []
    assert built >= 60  # the scan sees the producers (a broken scan would pass vacuously)
    methods = {n for n, _ in inspect.getmembers(EventSink, inspect.isfunction) if not n.startswith("_")}
    assert methods == SINK_METHODS  # no event(kind, **fields), fault(key, ...) by name


def test_the_endpoints_changes_are_logged_as_mixed_and_unmixed_records(tmp_path: Path) -> None:
    """``control.endpoint`` names its changes by string (control cannot import twin's records);
    the process worker turns them into the typed ``Mixed`` / ``Unmixed`` records. A bed that
    mixes (MI 0.95) and then segregates (MI 0.5) logs one ``mixed`` event with the detector's
    numbers, then one ``unmixed``: a change mapped to the wrong record, or to none, fails here."""
    b = Boxes("auto")
    b.mill_at(10.0)
    with RunLog(tmp_path / "run") as log:
        pw = ProcessWorker(queue.Queue(), MITrend(), b.frames, b.view, RunEvents(log, LiveState()))
        for i in range(450):  # 45 s at 10 fps: mixed for 30 s, then segregated
            t = i / 10.0
            pw.process(CameraReading(t, i, reading((0.95 if t < 30.0 else 0.5) + 0.005 * (-1) ** i)))
    ends = [e for e in read_events(tmp_path / "run") if e["kind"] in (Mixed.kind, Unmixed.kind)]
    assert [e["kind"] for e in ends] == ["mixed", "unmixed"], ends
    mixed, unmixed = ends
    assert mixed["t_s"] < 30.0 and mixed["mixing_time_s"] < mixed["t_s"] and mixed["plateau_mi"] > 0.9
    assert unmixed["t_s"] > 30.0 and unmixed.get("mixing_time_s") is None and "plateau" in unmixed["reason"]
    rows = read_frames(tmp_path / "run")
    assert [r["mixed"] for r in rows if r["t_s"] in (mixed["t_s"], unmixed["t_s"])] == [1.0, 0.0]


def test_an_unregistered_kind_is_read_back_whole_and_warned(tmp_path: Path, caplog) -> None:
    with caplog.at_level(logging.WARNING, logger="drumtwin.records"):
        rec = record_of("no_such_kind", 2.0, a=1, b="x")
        bad = record_of("operator", 2.0, action="stop", colour="red")  # a field the kind does not declare
    assert isinstance(rec, UntypedEvent) and isinstance(bad, UntypedEvent)
    assert "no_such_kind" in caplog.text and "operator" in caplog.text
    with RunLog(tmp_path / "run") as log:
        events = RunEvents(log, LiveState())
        events.publish(rec)  # written back whole
        events.publish(OperatorAction(t_s=3.0, action="stop"))
    got = read_events(tmp_path / "run")
    assert [(e["kind"], e["t_s"]) for e in got] == [("no_such_kind", 2.0), ("operator", 3.0)]
    assert got[0]["a"] == 1 and got[0]["b"] == "x"
    assert set(got[1]) == {"t_s", "wall_s", "kind", "action"}  # unset optional fields are left out, as before
    back = read_records(tmp_path / "run")
    assert isinstance(back[0], UntypedEvent) and back[0].data == {"a": 1, "b": "x"}
    assert back[1] == OperatorAction(t_s=3.0, action="stop")


PREVIOUS = ROOT / "tests" / "data" / "runlog-previous"
"""A run log written by the previous release's code (main of 2026-12-02 02:00 UTC, before the
typed producers: the demo in AUTO without the dashboard; frames.csv cut to its first 120 rows)."""


def test_a_run_log_of_the_previous_release_reads_back_as_typed_records(caplog) -> None:
    """The JSONL keys are unchanged: every line of a log written by main's code before this
    change is a record of its kind with the same fields (no ``UntypedEvent``), and it is the
    same JSON when written again."""
    with caplog.at_level(logging.WARNING, logger="drumtwin.records"):
        recs = read_records(PREVIOUS)
    assert caplog.text == ""
    lines = read_events(PREVIOUS)
    assert len(recs) == len(lines) >= 30
    assert not any(isinstance(r, UntypedEvent) for r in recs)
    assert {r.kind for r in recs} >= {"start", "decision", "mill_command", "mill_synced", "trend_settled", "stop"}
    for rec, line in zip(recs, lines, strict=True):
        payload = {k: v for k, v in line.items() if k not in ("t_s", "wall_s", "kind")}
        written = to_jsonable(event_fields(rec))
        assert {k: written[k] for k in payload} == payload, rec.kind  # every old key, the same value
        assert all(written[k] is None for k in set(written) - set(payload)), rec.kind  # fields added since: null
    rows = read_frames(PREVIOUS)
    assert rows and list(rows[0]) == list(FRAME_COLUMNS)


def test_report_and_compare_read_a_run_log_of_the_previous_release(tmp_path: Path) -> None:
    """``drumtwin report`` and ``drumtwin compare`` (their functions) on the previous release's
    log: the report lists its decisions and commands, the plot is written."""
    from twin.plots import plot_runs
    from twin.report import build_report, load_run

    run = load_run(PREVIOUS)
    assert run.n_frames == 120 and set(run.events.counts) >= {"decision", "mill_command"}
    assert run.notes == []  # no uid to check (a log of an earlier release): nothing skipped, nothing to say
    out = build_report([PREVIOUS], tmp_path / "report.html")
    html = out.read_text(encoding="utf-8")
    assert "runlog-previous" in html and "decision" in html
    png = plot_runs({"previous": PREVIOUS}, tmp_path / "cmp.png")
    assert png.stat().st_size > 10_000


def test_compare_prints_labels_and_paths_with_brackets_whole(tmp_path: Path) -> None:
    """``drumtwin compare`` on the previous release's log with a label and a plot path that
    rich markup would have read as style tags (``[a]``, ``[b]``)."""
    from tests.cli import cli

    png = tmp_path / "plots[b]" / "cmp[b].png"
    png.parent.mkdir()
    r = cli("compare", f"run[a]={PREVIOUS}", "--plot", png)
    assert r.code == 0, r.err
    assert "run[a]" in r.out and f"plot written to {png}" in r.err and png.is_file()


OTHER_CSVS = ("twin/cli/sim_cmds.py",)
"""The CLI modules that write CSVs of their own (``sim`` studies), not frames.csv (``drumtwin mi``
writes frames.csv's columns: ``twin.cli.mi_cmd``)."""


def test_the_csv_schema_is_defined_once() -> None:
    """Only ``FrameReading`` declares the frame columns: no other class in twin/ or tests/
    declares frame fields and no tuple/list literal lists column names (the old code had both,
    in twin/runlog.py and twin/state.py, kept equal only by a test). ``Panel`` is the dashboard's
    numbers panel (values folded from several record kinds), not a row."""
    columns = set(FRAME_COLUMNS) - {"t_s", "frame", "mode", "flags", "valid", "mi"}  # names too common to tell
    second = []
    for path, tree in _modules(TWIN, ROOT / "tests"):
        if str(path.relative_to(ROOT)) in OTHER_CSVS:
            continue
        for node in ast.walk(tree):
            if isinstance(node, ast.ClassDef) and node.name not in ("FrameReading", "Panel"):
                declared = {s.target.id for s in node.body if isinstance(s, ast.AnnAssign)
                            and isinstance(s.target, ast.Name)}
                if len(declared & columns) >= 4:
                    second.append((str(path.relative_to(ROOT)), node.name))
            if isinstance(node, (ast.Tuple, ast.List, ast.Set)):
                listed = {e.value for e in node.elts if isinstance(e, ast.Constant) and isinstance(e.value, str)}
                if len(listed & columns) >= 4:
                    second.append((str(path.relative_to(ROOT)), node.lineno))
    assert second == []
    assert FRAME_COLUMNS == ("t_s", "wall_s", *(f.name for f in fields(FrameReading)[1:]))
    assert set(SERIES) <= set(FRAME_COLUMNS) and "rpm_actual" in SERIES


def test_the_active_faults_the_log_and_the_dashboard_agree_through_any_sequence(tmp_path: Path) -> None:
    """One set of active faults (``ActiveFaults``, the sink's and the dashboard state's): through a
    seeded run of raises and clears of three faults, repeats included, the dashboard shows exactly
    the messages of the active faults (each its first), the log has one ``fault`` event per
    inactive -> active and one ``recovered`` per active -> inactive, and the count agrees. A second
    copy kept beside it (the old code kept ``RunEvents._active`` and ``LiveState._alarms``) drifts
    on a repeat or on the clear of an inactive fault, and fails here."""
    import random

    rng = random.Random(7)
    state = LiveState()
    active: dict[str, str] = {}
    expect: list[tuple[str, float, str]] = []
    with RunLog(tmp_path / "run") as log:
        events = RunEvents(log, state)
        for i in range(200):
            key, t = rng.choice(("mill_link", "camera_stopped", "vision_lost")), float(i)
            if rng.random() < 0.5:
                events.publish(FaultRaised(t_s=t, fault=key, message=f"{key} lost at {i}"))
                if key not in active:
                    active[key] = f"{key} lost at {i}"
                    expect.append(("fault", t, key))
            else:
                events.publish(FaultCleared(t_s=t, fault=key, message="back"))
                if active.pop(key, None) is not None:
                    expect.append(("recovered", t, key))
            assert sorted(state.alarms) == sorted(active.values()) and events.active() == set(active), i
    assert [(e["kind"], e["t_s"], e["fault"]) for e in read_events(tmp_path / "run")] == expect
    assert events.n_faults == sum(kind == "fault" for kind, _, _ in expect) > 10


def test_a_fault_is_raised_once_and_the_dashboard_shows_the_same_set(tmp_path: Path) -> None:
    state = LiveState()
    with RunLog(tmp_path / "run") as log:
        events = RunEvents(log, state)
        assert events.faults is state.faults and isinstance(events.faults, ActiveFaults)
        events.publish(FaultRaised(t_s=1.0, fault="mill_link", message="mill link lost", url="loop://"))
        events.publish(FaultRaised(t_s=1.5, fault="mill_link", message="mill link lost again", url="loop://"))
        assert state.alarms == ("mill link lost",) and events.active() == {"mill_link"}
        events.publish(FaultCleared(t_s=2.0, fault="mill_link", message="restored"))
        events.publish(FaultCleared(t_s=2.5, fault="mill_link", message="restored"))
    got = [(e["kind"], e["t_s"], e.get("url")) for e in read_events(tmp_path / "run")]
    assert got == [("fault", 1.0, "loop://"), ("recovered", 2.0, None)]
    assert state.alarms == () and events.n_faults == 1


def _same(a: object, b: object) -> bool:
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a):
        return math.isnan(b)
    return a == b or (isinstance(a, float) and b == pytest.approx(a, rel=1e-12))


def test_one_frame_traced_to_the_csv_row_the_jsonl_and_the_dashboard(tmp_path: Path) -> None:
    """One camera reading through the process worker: the one record it publishes is the
    CSV row cell for cell, the trend event it causes is in the JSONL at its time, and the
    dashboard's state (plot point and numbers panel) shows the same values."""
    state = LiveState()
    b = Boxes("manual")
    b.mill_at(7.5)
    with RunLog(tmp_path / "run") as log:
        events = RunEvents(log, state)
        pw = ProcessWorker(queue.Queue(), MITrend(), b.frames, b.view, events)
        rec = pw.process(CameraReading(4.25, 17, reading(0.83, slope=31.5)))
    assert isinstance(rec, FrameReading)
    [row] = read_frames(tmp_path / "run")
    csv_value = {bool: lambda v: 1.0 if v else 0.0, tuple: lambda v: ";".join(v) or None}
    for f in fields(FrameReading):
        v = getattr(rec, f.name)
        want = csv_value.get(type(v), lambda v: v)(v)
        assert _same(float(want) if isinstance(want, int) and not isinstance(want, bool) else want, row[f.name]), f.name
    assert row["mi"] == pytest.approx(0.83) and row["rpm_actual"] == 7.5 and row["frame"] == 17.0
    assert row["mode"] == "manual" and row["wall_s"] > 0
    [ev] = [e for e in read_events(tmp_path / "run") if e["kind"] == TrendUnsettled.kind]
    assert ev["t_s"] == rec.t_s and ev["level"] == pytest.approx(rec.trend_mi)
    snap = state.snapshot()
    assert snap.history["t_s"][-1] == rec.t_s and snap.history["mi"][-1] == pytest.approx(rec.mi)
    assert snap.history["rpm_actual"][-1] == 7.5 and snap.history["trend_mi"][-1] == pytest.approx(rec.trend_mi)
    p = snap.panel
    assert (p.t_s, p.mi, p.slope_deg, p.trend_state, p.light_state) == (4.25, rec.mi, 31.5, "unsettled", "ok")


def test_the_demo_start_plan_waits_for_the_mill_record_then_starts_the_drive_and_the_mill() -> None:
    """The demo's start (``twin.run.main.DemoStart``): nothing is started before the mill worker's
    first connected ``MillState`` record; then the front panel, then the operator's Start."""
    import threading

    from twin.records import Bus, MillState
    from twin.run.main import DemoStart

    calls: list[str] = []

    class Plant:
        def start_drive(self) -> None:
            calls.append("drive")

    class Controls:
        def start_mill(self) -> None:
            calls.append("start")

    class Loop:
        stop_event = threading.Event()
        controls = Controls()

    bus = Bus()
    plan = DemoStart(Plant(), connect_timeout_s=30.0)  # type: ignore[arg-type]
    bus.subscribe(plan.record)
    bus.publish(MillState(t_s=0.0, state="connecting", connected=False, setpoint_rpm=None, actual_rpm=None))
    done = threading.Thread(target=plan.execute, args=(Loop(),))
    done.start()
    done.join(0.3)
    assert done.is_alive() and calls == []  # still waiting: the board was not read yet
    bus.publish(MillState(t_s=0.5, state="running", connected=True, setpoint_rpm=5.0, actual_rpm=5.0))
    done.join(5.0)
    assert not done.is_alive() and calls == ["drive", "start"]


def test_run_config_has_no_untyped_bag() -> None:
    """Test seams are the typed ``twin.run.settings.Seams``, not a ``RunConfig.extra`` dict."""
    from twin.config import RunConfig
    from twin.run.settings import Seams

    assert "extra" not in {f.name for f in fields(RunConfig)}
    assert {f.name for f in fields(Seams)} >= {"supervisor", "calibrate", "whatif_study", "mismatch", "on_started"}
    with pytest.raises(TypeError):  # a misspelt supervisor setting is refused, not ignored
        from twin.run.settings import supervisor_config

        supervisor_config(Seams(supervisor={"seg_levle": 0.9}))


@pytest.mark.slow
def test_mypy_refuses_a_misspelt_record_kind_or_field(tmp_path: Path) -> None:
    """What the typed producers buy: a misspelt field, a wrong type or a kind that does not
    exist is a mypy error at the call (with ``sink.event("mill_refused", reasn=...)`` it was a
    runtime ``UntypedEvent``). The correct record passes."""
    from mypy import api

    snippet = tmp_path / "producer.py"
    snippet.write_text(
        "from twin.records import FaultRaised, MillRefused\n"
        "MillRefused(t_s=0.0, command='stop', source='operator', reason='NAK')\n"
        "MillRefused(t_s=0.0, command='stop', source='operator', reasn='NAK')\n"
        "FaultRaised(t_s='soon', fault='mill_link', message='lost')\n"
        "from twin.records import MillRefussed\n",
        encoding="utf-8",
    )
    limit = sys.getrecursionlimit()  # mypy's main raises it to 2**14 for the whole process, which let
    try:  # a 5000-deep TOML parse in later tests of the worker (test_safety_input's "nested too deeply")
        out, _, status = api.run([str(snippet), "--follow-imports=silent", "--no-incremental", "--config-file=",
                                  "--ignore-missing-imports", "--cache-dir", str(tmp_path / "cache")])
    finally:
        sys.setrecursionlimit(limit)
    errors = sorted({int(line.split(":")[1]) for line in out.splitlines() if ": error:" in line})
    assert status == 1 and errors == [3, 4, 5], out


def test_the_decision_record_declares_exactly_the_keys_control_writes() -> None:
    """``DecisionMade.of`` is the one record built from a dict: control cannot import twin, so
    a decision's JSON form is ``control.supervisor.Decision.as_dict`` (pinned by control's tests).
    The record declares exactly its keys (``kind`` as ``decision``) and its JSONL line is that
    dict, so a key added in control fails here instead of crashing the supervisor worker."""
    from control.decision import Action, Decision, Mode, SupervisorInputs
    from control.objective import RpmPrediction

    full = Decision(1.0, Mode.AUTO, Action.SET_RPM, "move", "why", rpm=12.0, target_rpm=15.0,
                    inputs=SupervisorInputs(mill_connected=True), predictions={5.0: 0.3},
                    chosen=RpmPrediction(12.0, 0.9, 60.0, 700.0, 0.5), prediction_t_s=0.5)
    bare = Decision(3.0, Mode.MANUAL, Action.STOP, "safe", "y")
    declared = {f.name for f in fields(DecisionMade)} - {"t_s"}
    for d in (full, bare):
        data = d.as_dict()
        assert {("decision" if k == "kind" else k) for k in data} - {"t_s"} == declared
        rec = DecisionMade.of(d)
        line = to_jsonable(event_fields(rec))
        want = to_jsonable({("decision" if k == "kind" else k): v for k, v in data.items() if k != "t_s"})
        assert {k: v for k, v in want.items() if k in line} == line and rec.t_s == d.t_s
        assert set(want) - set(line) <= {f.name for f in fields(DecisionMade) if f.metadata.get("optional")}


def test_the_dashboard_plots_draw_every_plot_series_of_the_frame_record() -> None:
    """The plots' history (``Snapshot.history``) is keyed by ``SERIES``, the ``FrameReading`` fields
    marked ``plot`` (derived, not declared again). Two frames whose every series has a value of its
    own, pushed through the real layout on a viser server: each series is drawn exactly once,
    against the frames' times. A renamed field or a misspelt key (a KeyError), a series left out
    or drawn twice fails here, not at run time."""
    import numpy as np
    import viser

    from twin.dashboard.layout import Layout

    assert set(LiveState().snapshot().history) == set(SERIES)
    values = {k: 0.05 * (i + 1) for i, k in enumerate(SERIES) if k != "t_s"}
    state = LiveState()
    for i, t in enumerate((1.0, 2.0)):
        state.record(FrameReading(t_s=t, frame=i, mi_sigmoid=0.8, mi_linear=0.8, d_px=3.0, dsigma_px=1.0,
                                  concentration=0.5, valid=True, trend_rate=0.0, mode="auto", flags=(),
                                  **values))  # type: ignore[arg-type]
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        layout = Layout(server)
        assert layout.push(state.snapshot(), {"camera": None, "twin": None, "hist": None}, plots=True)
        plots = [p.data for p in (layout._mi_plot, layout._rpm_plot, layout._slope_plot)]
    finally:
        server.stop()
    drawn = []
    mi_t, golden, *mi_rest = plots[0]  # the MI plot's first series: the golden batch's curve (dashboard.history)
    assert np.isnan(golden).all()  # no rig history here: nothing drawn for it
    for t, *ys in [(mi_t, *mi_rest), *plots[1:]]:
        assert np.array_equal(t, [1.0, 2.0])
        for y in ys:
            assert len(y) == 2 and y[0] == y[1]
            drawn.append(float(y[0]))
    assert sorted(drawn) == sorted(values.values())


def test_the_descriptors_are_derived_from_the_record_declarations() -> None:
    """Issue 41 item 6: each logged kind's descriptor lists exactly its fields (then the run log's
    wall_s and run_uid) with the unit declared beside the field and a source (the field's own, else
    its class's producer): a field added, renamed or given another unit is described without a
    second table. A record class declared here is described the same way."""
    from collections.abc import Mapping
    from dataclasses import dataclass

    from twin.descriptors import LOG_KEYS, data_keys, descriptors
    from twin.records import Record, opt, unit

    desc = descriptors(FRAME_COLUMNS)
    assert set(desc) == {"frame"} | {k for k, c in KINDS.items() if c.logged and c is not FrameReading}
    for kind, cls in KINDS.items():
        if not cls.logged:
            continue
        keys = desc[kind]["data_keys"]
        assert list(keys) == [f.name for f in fields(cls)] + list(LOG_KEYS), kind
        for f in fields(cls):
            assert keys[f.name]["units"] == f.metadata["unit"], (kind, f.name)
            assert keys[f.name]["source"] == (f.metadata.get("source") or cls.producer) != "", (kind, f.name)
            assert keys[f.name].get("optional", False) == bool(f.metadata.get("optional")), (kind, f.name)

    @dataclass(frozen=True, kw_only=True)
    class Probe(Record):
        producer = "a test"
        depth_mm: float = unit("mm", "how deep")
        counts: Mapping[str, int] | None = opt("", "by name")
        names: tuple[str, ...] = unit("", "some names", source="elsewhere")

    got = data_keys(Probe)
    assert got["depth_mm"] == {"dtype": "number", "shape": [], "units": "mm", "source": "a test", "doc": "how deep"}
    assert got["counts"]["dtype"] == "object" and got["counts"]["optional"] is True
    assert got["names"]["dtype"] == "array" and got["names"]["source"] == "elsewhere"
    assert data_keys(Probe, csv=True)["names"]["dtype"] == "string"  # one ';'-joined cell in a CSV

    @dataclass(frozen=True, kw_only=True)
    class Odd(Record):
        blob: bytes = unit("", "no JSON type")

    with pytest.raises(TypeError, match="blob"):
        data_keys(Odd)
