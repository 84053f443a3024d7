"""The bad-input sweep's cases (tests/test_bad_input_sweep.py, issue 26): the CLI's click command tree
walked for every leaf command and its parameters, bad values by type and option name, each command's
base arguments (valid and quick: a case differs from a success only in its swept value), the documented
successes, and the distinct bases the sweep's negative control runs."""

from __future__ import annotations

import enum
import types
import typing
from dataclasses import dataclass
from pathlib import Path

import typer

from tests.conftest import (
    BENCH_DASHBOARD_ARGS,
    BENCH_MEMORY_ARGS,
    BENCH_TREND_ARGS,
    BENCH_TWIN_ARGS,
    COMMISSION_PMMA_ARGS,
)
from twin.cli import app


# -- the command tree -----------------------------------------------------------------------
@dataclass(frozen=True)
class Param:
    """One option or argument of one command: ``path`` the command words, ``group`` True for
    a parameter of the command's group (``mill URL ...``), ``kind`` float/int/path/str/flag."""

    path: tuple[str, ...]
    name: str
    opt: str | None  # "--duration"; None for a positional argument
    kind: str
    group: bool = False


def _kind(annotation: object) -> str:
    args = typing.get_args(annotation)
    if typing.get_origin(annotation) in (typing.Union, types.UnionType):
        annotation = next(a for a in args if a is not type(None))
        args = typing.get_args(annotation)
    if typing.get_origin(annotation) is list:
        annotation = args[0]
    if isinstance(annotation, type) and issubclass(annotation, enum.Enum):
        return "choice"
    return {float: "float", int: "int", Path: "path", str: "str", bool: "flag"}.get(annotation, repr(annotation))


def command_tree() -> list[tuple[tuple[str, ...], list[Param]]]:
    """(command words, its parameters with its groups') for every leaf command."""
    out: list[tuple[tuple[str, ...], list[Param]]] = []

    def walk(cmd, path: tuple[str, ...], inherited: list[Param]) -> None:
        own = [Param(path, p.name, p.opts[0] if p.opts[0].startswith("-") else None,
                     "flag" if getattr(p, "is_flag", False) else _kind(p.type_descriptor.annotation))
               for p in cmd.params]
        if hasattr(cmd, "commands"):
            group = [Param(p.path, p.name, p.opt, p.kind, True) for p in own]
            for name, sub in cmd.commands.items():
                walk(sub, (*path, name), inherited + group)
        else:
            out.append((path, inherited + own))

    walk(typer.main.get_command(app), (), [])
    return out


# Mixers a config may describe that no twin can hold (issue 42): (drum mm, particle mm, count per class,
# by share). Each is refused alike by every command that reads a config (test_a_config_is_refused_alike...).
HOSTILE_MIXERS: dict[str, tuple[float, float, int, bool]] = {
    "speck": (250, 1e-9, 122, False),  # particles of 1e-9 mm: `run` ran on with MI NaN
    "crowd": (10_000, 8.8, 100_000, False),  # 2 x 100,000 discs in a 10 m drum: `sim` hung placing them
    "fine": (250, 0.5, 50_000, False),  # 2 x 50,000 discs of 0.5 mm: hung as well
    "fine_few": (250, 0.5, 50, False),  # a few of them: too light for the DEM's step
    "underflow": (250, 1e-300, 0, True),  # by share: their area underflows to 0 (a division by zero)
}


# -- what each command needs to run (fast) when the swept value is accepted ------------------
# A leaf command's base arguments: valid and quick, so a case differs from a success only in
# the swept value. ``{...}`` names come from ``env``.
BASE: dict[tuple[str, ...], list[str]] = {
    ("run",): ["--no-dashboard", "--duration", "1", "--speed", "10", "--log", "{out}/run-{case}"],
    ("compare",): ["{okrun}", "--plot", "{out}/cmp-{case}.png"],
    ("report",): ["{okrun}", "--out", "{out}/report-{case}.html"],
    ("mi",): ["{synth}"],
    ("sim",): ["--duration", "0.2", "--size", "64", "--fps", "5"],
    ("calibrate",): ["{synth}", "--rpm", "10", "--max-evals", "1", "--max-frames", "1", "--spin-up-s", "0.5",
                     "--window-s", "0.5"],
    ("whatif",): ["--rpm", "5", "--duration", "0.5", "--workers", "1"],
    ("mill-emulator",): ["--tcp", "0", "--duration", "0.2"],
    ("bench", "dashboard"): BENCH_DASHBOARD_ARGS,  # its base run is shared with twin/test_live_browser.py's bench test
    ("bench", "memory"): BENCH_MEMORY_ARGS,  # its base run is shared with twin/test_memory.py's bench test
    ("bench", "vision"): ["--seconds", "0.1"],
    ("bench", "twin"): BENCH_TWIN_ARGS,  # ... with sim/test_cli.py's
    ("bench", "trend"): ["--sequences", "1", "--real-seeds", "0"],
    ("bench", "link"): ["--requests", "5"],
    ("bench", "report"): ["--rows", "50", "--runs", "1"],
    ("bench", "catalogue"): ["--runs", "5"],
    ("runs", "list"): ["--runs-dir", "{tmp}"],
    ("runs", "show"): ["okrun", "--runs-dir", "{tmp}"],
    ("runs", "tag"): ["okrun", "lot=1", "--runs-dir", "{tmp}"],
    ("runs", "note"): ["okrun", "a note", "--runs-dir", "{tmp}"],
    ("runs", "golden"): ["okrun", "--runs-dir", "{tmp}"],
    ("runs", "rebuild"): ["--runs-dir", "{tmp}"],
    ("classes", "suggest"): ["{synth}", "--frames", "1"],
    ("mill", "status"): [],
    ("mill", "set-rpm"): ["10"],
    ("mill", "start"): [],
    ("mill", "stop"): [],
    ("mill", "check"): [],
    ("commission",): ["{frames}", *COMMISSION_PMMA_ARGS, "--out", "{out}/commission-{case}"],
    ("bench", "commission"): ["--rig", "discs", "--json"],  # a small rendered rig of discs: seconds
}
GROUP_BASE: dict[tuple[str, ...], list[str]] = {("mill",): ["{mill}"], ("mill", "check"): ["{drive}"]}
# A value of one option only means something next to another (run --video needs --mill).
CONTEXT: dict[tuple[tuple[str, ...], str], list[str]] = {
    (("run",), "camera"): ["--mill", "{mill}"],
    (("run",), "video"): ["--mill", "{mill}", "--video", "{video}"],  # the case's --video comes last: it wins
    (("run",), "mill"): ["--video", "{video}", "--mill", "{mill}"],
    (("run",), "control_token"): ["--host", "0.0.0.0"],
}
# ... or needs other base arguments (a pty's --link is no option of a TCP emulator).
REAL_RUN = ["--no-dashboard", "--duration", "1", "--log", "{out}/run-{case}"]  # a video and a mill: no --speed
BASE_FOR: dict[tuple[tuple[str, ...], str], list[str]] = {
    (("run",), "camera"): REAL_RUN,
    (("run",), "video"): REAL_RUN,
    (("run",), "mill"): REAL_RUN,
    (("mill-emulator",), "link"): ["--pty", "--duration", "0.2"],
    (("bench", "trend"), "frames"): BENCH_TREND_ARGS,  # ... with control/test_cli.py's
    (("bench", "trend"), "config"): BENCH_TREND_ARGS,
    (("run",), "port"): ["--duration", "1", "--speed", "10", "--log", "{out}/run-{case}",  # with the dashboard,
                         "--port", "{port}"],  # on a free port (a case's --port comes last: it wins)
}
# Parameters that name a file the command writes (bad values: a path under a regular file,
# a directory); every other path is read (bad values: missing, a directory, empty, garbage).
OUTPUTS = {
    ("run", "log"), ("compare", "plot"), ("report", "out"), ("mi", "csv_out"), ("mi", "plot"), ("mi", "overlay_video"),
    ("sim", "csv_out"), ("sim", "video"), ("whatif", "csv_out"), ("whatif", "plot"),
    ("classes", "preview"),
    ("bench", "keep"),
    ("commission", "out"),
}
FLOATS = ["abc", "nan", "inf", "-inf", "1e308", "-1e308"]
INTS = ["abc", "1.5", "-1", "99999999999999999999"]
READ_PATHS = ["{missing}", "{dir}", "{empty}", "{garbage}"]
CONFIGS = ["{missing}", "{dir}", "{garbage}", "{syntax}", "{deep}", "{unknown_key}", "{unknown_table}",
           "{wrong_type}", "{roi_overflow}", "{roi_nan}", "{negative}", "{drum_bad}", "{drum_huge}",
           "{truncated}", "{classes_bad}", *(f"{{{k}}}" for k in HOSTILE_MIXERS)]
IMAGES = ["{missing}", "{empty}", "{garbage}", "{truncated_jpg}", "{garbage_jpg}", "{garbage_avi}"]
WRITE_PATHS = ["{under_file}", "{dir}"]
# Bad values of string options, by option name (a new string option needs an entry).
STRING_VALUES: dict[str, list[str]] = {
    "camera": ["99", "rtsp://127.0.0.1:{closed}/x", "no-such-device"],
    "mill": ["bogus://x", "socket://127.0.0.1:{closed}", "/dev/no-such-tty", " "],
    "url": ["bogus://x", "socket://127.0.0.1:{closed}", "/dev/no-such-tty", "modbus:/dev/x?profile=nope",
            "socket://999.1.1.1:5"],
    "engine": ["warp", ""],
    "mode": ["turbo", ""],
    "case": ["Z", ""],
    "host": ["999.1.1.1", "a b", ""],
    "control_token": [""],
    "scheduler": ["garbage", "tcp://127.0.0.1:{closed}", "http://127.0.0.1:80", "tcp://999.1.1.1:8786"],
    "drive": ["no-such-drive", "../../etc/passwd"],
    "roi": ["1,2", "a,b,c", "nan,nan,nan", "1e308,1e308,1e308", "-5,-5,-5", "10,10,0"],
    "bed": ["zzz"],
    "rpm": ["a,b", "nan", "", "-5", "1e308", "5,,10"],
    "faults": ["zzz=1", "corrupt=2", "delay=-1", "disconnect=x"],
    "modbus": ["no-such-drive"],
    "link": ["{under_file}/mill", "{dir}"],
    "source": ["zzz"],
    "runs": ["{missing}", "{file}", "{dir}", "{badrun}", "x={missing}"],
    "title": [],  # free text: no value is bad
    "label": [""],  # free text, but not none
    "objective": ["fastest", ""],
    # the run catalogue (issue 40): a file that is no catalogue, a directory, a path under a file, another
    # database, a server that does not answer
    "catalogue": ["{garbage}", "{dir}", "{under_file}/c.sqlite", "mysql://x/y", "postgresql://nobody@127.0.0.1:{closed}/x"],
    "rig": [""],
    "tag": ["=x", ""],
    "tags": ["=x", "nokey", ""],
    "since": ["yesterday", ""],
    "until": ["yesterday", ""],
    "ended": ["maybe", ""],
    "run": ["no-such-run", ""],
    "text": [],  # free text: no value is bad
}
# Bad values of number options beyond FLOATS / INTS: finite numbers outside the option's range.
RANGE_VALUES: dict[tuple[str, str], list[str]] = {
    ("calibrate", "end_friction"): ["-0.5", "5.5"],  # friction of the end plates: [0, 5]
    ("sim", "end_friction"): ["-0.5", "5.5"],
}
# Parameters whose values are read as images/videos or configs.
IMAGE_PARAMS = {("mi", "source"), ("calibrate", "source"), ("classes", "source"), ("bench", "frames"),
                ("commission", "source")}

# (command words, option, value) -> why exit 0 is right. Everything else must be exit 2.
DOCUMENTED_SUCCESS: dict[tuple[str, str, str], str] = {
    ("report", "runs", "{badrun}"): "issue 42: a log is read whatever it holds; its start event is readable, "
    "the rest is skipped and counted in a note on the run (exit 2 only when nothing in the dir is readable)",
    ("compare", "runs", "{badrun}"): "the same",
    # issue 40: a catalogue that is found unusable only when used is a warning for a run (it runs and logs,
    # the folder is indexed later), and report/compare of folders never open one
    ("run", "--catalogue", "{garbage}"): "a run goes on without its catalogue: a warning and a "
    "catalogue_unavailable record; 'runs list' indexes its folder later",
    ("run", "--catalogue", "postgresql://nobody@127.0.0.1:{closed}/x"): "the same",
    **{(cmd, "--catalogue", v): "a report or comparison of run folders needs no catalogue"
       for cmd in ("report", "compare") for v in ("{garbage}", "postgresql://nobody@127.0.0.1:{closed}/x")},
    **{(cmd, "--runs-dir", "{dir}"): "an empty folder of runs is a folder of runs (none listed)"
       for cmd in ("runs list", "runs rebuild", "report", "compare")},
    ("runs rebuild", "roots", "{dir}"): "the same",
}


@dataclass(frozen=True)
class Case:
    argv: tuple[str, ...]
    key: tuple[str, str, str]  # (command words, option or argument name, value)

    @property
    def id(self) -> str:
        return " ".join(self.key)[:90]


def _values(p: Param) -> list[str]:
    where = (p.path[0], p.name)
    if p.kind == "flag":
        return []
    if p.kind == "float":
        return FLOATS + RANGE_VALUES.get(where, [])
    if p.kind == "choice":
        return ["zzz", ""]
    if p.kind == "int":
        return INTS + (["{busy}"] if p.name in ("port", "tcp") else [])
    if p.kind == "path":
        if where == ("run", "log"):  # a directory is written: a file there, or one holding a run log
            return ["{under_file}", "{file}", "{badrun}"]
        if where in OUTPUTS:
            return WRITE_PATHS
        if p.name == "config":
            return CONFIGS
        if where in IMAGE_PARAMS or (p.path[0] == "run" and p.name == "video"):
            return IMAGES
        return READ_PATHS
    if p.kind == "str":
        if where in IMAGE_PARAMS:
            return IMAGES
        if p.path == ("runs", "rebuild") and p.name == "catalogue":  # rebuild keeps a corrupt file aside and
            return [v for v in STRING_VALUES["catalogue"] if v != "{garbage}"]  # makes it anew: exit 0
        return STRING_VALUES[p.name]
    raise AssertionError(f"{' '.join(p.path)} {p.opt or p.name}: no bad values for type {p.kind}")


def sweep_cases() -> list[Case]:
    cases: list[Case] = []
    for path, params in command_tree():
        group = GROUP_BASE.get(path, GROUP_BASE.get(path[:1], []))
        for p in params:
            base = BASE_FOR.get((path, p.name), BASE[path])
            for value in _values(p):
                ctx = CONTEXT.get((path, p.name), [])
                key = (" ".join(path), p.opt or p.name, value)
                if p.group:  # mill [OPTIONS] URL ...: the group's own parameter, before the subcommand
                    head = [path[0], *([value] if p.opt is None else [p.opt, value, *group]), *path[1:]]
                    cases.append(Case((*head, *base), key))
                    continue
                if p.opt is None:  # a positional argument replaces the base's first one
                    rest = [a for a in base if a != base[0]] if base and not base[0].startswith("-") else base
                    cases.append(Case((*path[:1], *group, *path[1:], value, *rest, *ctx), key))
                else:
                    cases.append(Case((*path[:1], *group, *path[1:], *base, *ctx, p.opt, value), key))
    return cases


CASES = sweep_cases()


def base_runs() -> dict[str, tuple[str, ...]]:
    """Every distinct base a case is built on (command, base arguments, context)."""
    out: dict[str, tuple[str, ...]] = {}
    for path, params in command_tree():
        group = GROUP_BASE.get(path, GROUP_BASE.get(path[:1], []))
        for p in params:
            if (" ".join(path), p.opt or p.name) in BASE_SKIP:
                continue
            argv = (*path[:1], *group, *path[1:], *BASE_FOR.get((path, p.name), BASE[path]),
                    *CONTEXT.get((path, p.name), []))
            out.setdefault(" ".join(argv)[:90], argv)
    return out


# Bases that cannot succeed here or are too slow for every run of the suite.
NO_CAMERA = "no camera on this machine: the camera cases fail on the camera, by construction"
BASE_SKIP = {("run", "--camera"): NO_CAMERA}
SLOW_BASES = ("bench dashboard", "bench memory", "run", "commission", "bench commission")
BASES = base_runs()
