"""The cross-rig bench run with another checkout's vision: the "before" column of the bench's table.

``drumtwin bench vision --rigs`` measures this tree's ``classes suggest`` and meter on rigs made
from the real frames. To show today's code on the same bench beside it, this script imports
the ``vision`` package of ``OLD`` (a checkout of the code before, e.g. ``git worktree add
/tmp/oldvision 07b7317``) and lays this tree's bench modules over it (the rigs, the bench and
what they need that the old package lacks: ``synthetic`` for the synthetic rigs' truth,
``bedframe``/``colourfit``/``loro`` for its records), so that the frames, the truth and the
counting are this tree's and the learning and measuring are the old code's::

    .venv/bin/python -m scripts.rigs_before /tmp/oldvision [--lights setup,x0.7,...] [--rigs R,...] > before.json
    .venv/bin/python -m scripts.rigs_before before.json --table docs/numbers/rigs.json

The old light estimates have no classes' disagreement, so the leave-one-rig-out rows are left out.
``--table`` prints the two side by side (markdown, the issue's aims: at the set-up light the
flagged share, at x0.7, x1.3 and the white-balance shifts the share within 3 % of R).
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
OVERLAID = ("synthetic", "colourfit", "bedframe", "rigs", "loro", "rigbench")
"""This tree's modules laid over the old package, in import order."""


AIMS = ("setup", "x0.7", "x1.3", "wb_warm", "wb_cool", "wb_green")
"""The lights of the issue's aims, in the table's order."""


def table(before: dict, after: dict) -> list[str]:
    """Markdown: one row per suite, rig and light of :data:`AIMS` that both ran; at the set-up
    light the flagged share (aim <= 2 %), else the share within 3 % of R (aim >= 90 %), before ->
    after, and whether after meets the aim."""
    out = ["| suite | rig | light | number (aim) | before | after | aim met |", "|---|---|---|---|---:|---:|---|"]
    for suite in ("real", "synthetic"):
        for rig, row in after.get(suite, {}).items():
            old_row = before.get(suite, {}).get(rig, {})
            for light in AIMS:
                if light not in row:
                    continue
                key, aim = ("flagged", "<= 2 %") if light == "setup" else ("within_3pct", ">= 90 %")
                new = row[light][key]
                old = old_row[light][key] if light in old_row else None
                met = "yes" if (new <= 0.02 if light == "setup" else new >= 0.9) else "**no**"
                was = "-" if old is None else f"{100 * old:.1f} %"
                out.append(f"| {suite} | {rig} | {light} | {key} ({aim}) | {was} | {100 * new:.1f} % | {met} |")
    return out


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(prog="python -m scripts.rigs_before", description=(__doc__ or "").split("\n\n")[0])
    ap.add_argument("old", type=Path, help="a checkout whose vision/ is measured")
    ap.add_argument("--lights", default="", help="comma-separated lights (default: every light of the bench)")
    ap.add_argument("--rigs", default="", help="comma-separated real rigs, e.g. teal-white/frame2048x1948 "
                    "(default: every rig of the bench, the synthetic ones too)")
    ap.add_argument("--table", type=Path, metavar="AFTER", help="OLD is a JSON this script printed: print it "
                    "beside AFTER (the bench's JSON, or a kept docs/numbers/rigs.json)")
    args = ap.parse_args(argv)
    if args.table is not None:
        before, after = (json.loads(p.read_text(encoding="utf-8")) for p in (args.old, args.table))
        print("\n".join(table(before.get("result", before), after.get("result", after))))  # a kept record or bare
        return
    if not (args.old / "vision" / "meter.py").is_file():
        ap.error(f"{args.old} has no vision/meter.py")
    sys.path.insert(0, str(args.old.resolve()))
    sys.modules.pop("vision", None)
    import vision

    assert Path(vision.__file__).resolve().is_relative_to(args.old.resolve()), vision.__file__
    for name in OVERLAID:
        spec = importlib.util.spec_from_file_location(f"vision.{name}", REPO / "vision" / f"{name}.py")
        assert spec is not None and spec.loader is not None
        mod = importlib.util.module_from_spec(spec)
        sys.modules[spec.name] = mod
        spec.loader.exec_module(mod)
    rb = sys.modules["vision.rigbench"]
    measure = rb.measure_light
    vars(rb)["measure_light"] = lambda setup, frames, light, _spreads, at_setup: measure(setup, frames, light, None,
                                                                                       at_setup)
    lights = tuple(v for v in args.lights.split(",") if v) or (*rb.LIGHTS, *rb.BEYOND)
    spec = sys.modules["vision.rigs"].RigSpec
    rigs = [spec(*n.split("/", 1)) for n in args.rigs.split(",") if n]  # "pair" or "pair/camera"
    res = rb.run_rig_bench(rigs=rigs or None, synthetic=[] if rigs else None, lights=lights,
                           log=lambda s: print(s, file=sys.stderr, flush=True))
    res.pop("loro", None)
    print(json.dumps(res, indent=1))


if __name__ == "__main__":
    main()
