"""Every row of the README's numbers tables has a source (issue 27): an entry in docs/numbers.md
with the command that reproduces it and the tests that back it; the rows that are cheap to
reproduce are reproduced here at the README's precision."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from tests.cli import cli

REPO = Path(__file__).resolve().parent.parent
README = REPO / "README.md"
NUMBERS = REPO / "docs" / "numbers.md"
NUMBER = re.compile(r"-?\d+(?:\.\d+)?")


def cells(line: str) -> list[str]:
    return [c.strip() for c in line.strip().strip("|").split("|")]


def readme_rows(text: str) -> dict[tuple[str, str], list[str]]:
    """(table, first cell) -> the row's cells, for every table under ``## Numbers``; a table
    is named by the bold word that opens the paragraph before it (``**Vision**``, ...)."""
    section = text.split("\n## Numbers\n", 1)[1].split("\n## ", 1)[0]
    rows: dict[tuple[str, str], list[str]] = {}
    name, in_table = None, False
    for line in section.splitlines():
        m = re.match(r"\*\*(\w+)\*\*", line)
        if m:
            name = m.group(1)
        if line.startswith("|"):
            c = cells(line)
            if not in_table:  # the header
                in_table = True
                continue
            if set("".join(c)) <= set("-: "):  # the separator
                continue
            assert name is not None, f"a numbers table without a **Name** paragraph before it: {line}"
            rows[(name, c[0])] = c
        else:
            in_table = False
    return rows


def mapping(text: str) -> dict[tuple[str, str], dict[str, str]]:
    out = {}
    lines = [ln for ln in text.splitlines() if ln.startswith("|")]
    head = cells(lines[0])
    assert head == ["table", "row", "kind", "reproduced by", "checked by"], head
    for ln in lines[2:]:
        c = dict(zip(head, cells(ln), strict=True))
        key = (c["table"], c["row"])
        assert key not in out, f"docs/numbers.md names {key} twice"
        out[key] = c
    return out


def test_the_parsers_find_the_tables_and_a_new_row_is_reported():
    text = README.read_text()
    rows = readme_rows(text)
    assert {t for t, _ in rows} == {"Vision", "Twin", "Trend"} and len(rows) >= 14
    added = text.replace("| Lacey index, 640x480 |", "| Lacey index, 320x240 | 999 | | | |\n| Lacey index, 640x480 |")
    assert set(readme_rows(added)) - set(mapping(NUMBERS.read_text())) == {("Vision", "Lacey index, 320x240")}


def test_every_readme_numbers_row_has_a_source_and_every_source_a_row():
    rows, src = readme_rows(README.read_text()), mapping(NUMBERS.read_text())
    missing = sorted(set(rows) - set(src))
    assert not missing, f"README numbers without an entry in docs/numbers.md: {missing}"
    stale = sorted(set(src) - set(rows))
    assert not stale, f"docs/numbers.md entries for rows the README no longer has: {stale}"


def test_every_source_names_a_command_and_tests_that_exist():
    for key, c in mapping(NUMBERS.read_text()).items():
        assert c["kind"] in ("speed", "accuracy"), key
        assert re.fullmatch(r"`drumtwin [^`]+`", c["reproduced by"]), (key, c["reproduced by"])
        tests = [t.strip() for t in c["checked by"].split(",") if t.strip()]
        assert tests, key
        for t in tests:
            path, _, name = t.partition("::")
            f = REPO / path
            assert f.is_file() and re.search(rf"^def {re.escape(name)}\(", f.read_text(), re.M), (key, t)
        if c["kind"] == "accuracy":  # reproduced by a test of this module or bounded by one
            assert any("test_readme_numbers.py" in t or "test_trend" in t for t in tests), key


def trend_row(cells_: list[str]) -> dict[str, str]:
    """The numbers of a trend row as shown: RMSE, lag 63 %, lag to 0.05, lock-out, coverage (%, if any)."""
    rmse, lag, lockout, cover = (NUMBER.findall(c) for c in cells_[1:5])
    out = {"rmse": rmse[0], "lag_s": lag[0], "lag05_s": lag[1], "lockout_s": lockout[0]}
    if cover:
        out["coverage_pct"] = cover[0]
    return out


def check_row(row: list[str], got: dict[str, float], prefix: str) -> None:
    """Each number of the row equals the bench's to half a unit of its last digit."""
    for k, s in trend_row(row).items():
        decimals = len(s.split(".")[1]) if "." in s else 0
        value = 100.0 * got[f"{prefix}_coverage"] if k == "coverage_pct" else got[f"{prefix}_{k}"]
        assert abs(value - float(s)) <= 0.5 * 10.0**-decimals + 1e-9, (row[0], k, s, value)


def check_bench_rows(args: tuple[str, ...], bench: str, kalman_row: str, ma_row: str) -> None:
    """``drumtwin bench trend --json ARGS``: the bench's numbers against the two README rows."""
    r = cli("bench", "trend", "--json", *args)
    assert r.code == 0, r.err
    got = json.loads(r.out)[bench]
    rows = readme_rows(README.read_text())
    check_row(rows[("Trend", kalman_row)], got, "kalman")
    check_row(rows[("Trend", ma_row)], got, "ma")


def test_the_synthetic_trend_rows_are_what_bench_trend_prints():
    """``drumtwin bench trend --real-seeds 0`` (8 seeded synthetic sequences, ~3 s of CPU)."""
    check_bench_rows(("--real-seeds", "0"), "synthetic", "Kalman trend, synthetic", "moving average (150), synthetic")


@pytest.mark.timeout(600)  # a hang guard: the classes of the 27 real frames (shared: tests/learned.py)
def test_the_real_trend_rows_are_what_the_real_bench_gives(memo_learning):
    """``drumtwin bench trend`` (the real bench: 2 draws of the 7 real-frame sequences)."""
    check_bench_rows(("--sequences", "1"), "real", "Kalman trend, real frames", "moving average (150), real frames")


def test_trend_row_parser_reads_the_readme_layout():
    assert trend_row(["x", "**0.021**", "**0.49 s** / -0.52 s", "1.17 s", "92.3 % (90-100 % per sequence)"]) == {
        "rmse": "0.021", "lag_s": "0.49", "lag05_s": "-0.52", "lockout_s": "1.17", "coverage_pct": "92.3"}
    assert "coverage_pct" not in trend_row(["x", "0.064", "3.20 s / 3.16 s", "6.13 s", "-"])
