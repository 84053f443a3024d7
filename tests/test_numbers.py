"""The numbers block of docs/numbers.md is generated (``python -m scripts.numbers``) from the
benches' JSON kept in docs/numbers/, and the deterministic ones are still what the bench prints.

No test here passes or fails on a speed: the block's frames/s and real-time factors are what the
bench printed on the machine and at the load its line names (house rule: speed goes into
``drumtwin bench ...``)."""

from __future__ import annotations

import json

import pytest

from scripts import numbers
from tests.cli import cli


def test_the_block_is_what_the_generator_makes_of_the_kept_bench_json() -> None:
    """A number typed into the block, a kept file changed without the block being generated
    again, or a bench of the page without its file fails here."""
    kept = numbers.load_kept()
    assert [rec["bench"] for rec in kept] == list(numbers.BENCHES)
    page = numbers.NUMBERS_MD.read_text(encoding="utf-8")
    assert numbers.block_of(page) == numbers.render(kept)


def test_each_kept_file_is_the_json_its_bench_command_prints() -> None:
    """Each file names its bench's command (``drumtwin bench NAME ... --json``, one that the CLI
    has), where and when it ran, and holds the bench's JSON: an object of numbers (and the odd
    word, such as the twin bench's clock)."""
    for rec in numbers.load_kept():
        name = rec["bench"]
        assert rec["command"] == numbers.command_of(name) and rec["command"].endswith(" --json")
        assert cli(*numbers.BENCHES[name][:2], "--help").code == 0, rec["command"]
        assert rec["cores"] >= 1 and rec["load_1m"] >= 0 and rec["commit"] and rec["measured_utc"]
        leaves = dict(numbers.flatten(rec["result"]))
        assert leaves and all(isinstance(v, (int, float, bool, str)) or v is None for v in leaves.values()), name
        assert sum(isinstance(v, (int, float)) for v in leaves.values()) > len(leaves) / 2, name


def test_the_generator_rewrites_only_its_block_and_shows_every_number() -> None:
    """Other sections of the page (other engineers' prose and measurements) are kept byte for byte;
    every leaf of a bench's JSON has its row, a nested one under its joined key."""
    rec = {"bench": "trend", "command": "drumtwin bench trend --json", "commit": "abc1234",
           "measured_utc": "2026-12-05 10:00", "cores": 2, "load_1m": 3.5,
           "result": {"synthetic": {"kalman_rmse": 0.0217846, "n": 8}, "fps": 2345.67, "ok": True, "gone": None}}
    block = numbers.render([rec])
    rows = [ln for ln in block.splitlines() if ln.startswith("| `")]
    assert rows == ["| `synthetic.kalman_rmse` | 0.02178 |", "| `synthetic.n` | 8 |", "| `fps` | 2,346 |",
                    "| `ok` | true |", "| `gone` | - |"]
    assert "load 3.5 on 2 cores" in block and "abc1234" in block
    page = f"# Numbers\n\nintro\n\n{numbers.BEGIN}\nold | stale\n{numbers.END}\n\n## Other section\n\nkept\n"
    new = numbers.with_block(page, block)
    assert new.startswith("# Numbers\n\nintro\n\n") and new.endswith(f"{numbers.END}\n\n## Other section\n\nkept\n")
    assert numbers.block_of(new) == block and "stale" not in new
    for broken in (page.replace(numbers.END, ""), page + numbers.BEGIN, page.replace(numbers.BEGIN, "")):
        with pytest.raises(ValueError, match="markers"):
            numbers.with_block(broken, block)


@pytest.mark.timeout(600)  # a hang guard: the classes of the 27 real frames (shared: tests/learned.py)
def test_the_kept_trend_numbers_are_what_bench_trend_prints(memo_learning) -> None:
    """The trend bench is deterministic (seeded sequences, the real frames' MI): the kept command
    run again gives the kept RMSE, lags, lock-out and coverage of the Kalman trend and the moving
    average, on the synthetic sequences and on the real ones (~6 s of CPU with the memo)."""
    kept = next(rec for rec in numbers.load_kept() if rec["bench"] == "trend")
    r = cli(*kept["command"].split()[1:])
    assert r.code == 0, r.err
    got = json.loads(r.out)
    assert set(got) == set(kept["result"]) == {"synthetic", "real"}
    for part in ("synthetic", "real"):
        assert got[part] == pytest.approx(kept["result"][part], rel=1e-9), part


def test_the_cross_rig_bench_is_one_row_per_rig_and_light() -> None:
    """The rigs bench's JSON (``drumtwin bench vision --rigs --json``) is shown one row per suite,
    rig and light with its numbers in the page's columns, the rest of it one row per number."""
    light = {"within_3pct": 0.952381, "flagged": 0.0, "holds_1pct": 1.0, "wrong_unflagged": 0.047619,
             "mi_err_median": 0.0123, "mi_err_p90": 0.05, "frames": 42}
    res = {"real": {"teal-white/rot90": {"classes": "teal, white", "setup": light, "x0.7": light | {"flagged": 0.5}}},
           "synthetic": {"red-blue": {"classes": "blue, red", "setup": light}},
           "summary": {"real": {"setup": {"rigs_missing_aim": ""}}}}
    rows = numbers.rig_rows(res)
    nums = "0.9524 | {} | 1 | 0.04762 | 0.0123 | 0.05 | 42 |"
    assert rows[2:5] == ["| real | teal-white/rot90 (teal, white) | setup | " + nums.format(0),
                         "| real | teal-white/rot90 (teal, white) | x0.7 | " + nums.format(0.5),
                         "| synthetic | red-blue (blue, red) | setup | " + nums.format(0)]
    assert "| `summary.real.setup.rigs_missing_aim` | `\"\"` |" in rows
