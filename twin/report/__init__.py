"""``drumtwin report RUN_DIR... --out report.html``: one self-contained HTML file per set of
runs (issue 24). It opens offline: plots are PNGs embedded as base64 data URIs, the style
sheet is inline, there is no script and no link out.

Sections, one column per run (several runs side by side): summary, MI (raw, Kalman trend,
twin), rpm (set, actual), bed slope (camera, twin), events (a timeline and a table),
endpoint and mixing time (the live ``mixed``/``unmixed`` events; for a run that logged
none, the same detector replayed offline on its raw MI, said so; the twin's predicted time to
mix at the rpm AUTO picked against the plant's, ``time_to_mix_check``), energy (used and
predicted, when the run logged any), configuration and versions.

A run dir cut short (``kill -9``: a partial last CSV line, no ``stop`` event, perhaps no
``metadata.json``) renders what was logged and says that the run did not end cleanly. Any
other damage (a line that is not an event, a cell that is not a number, a number no plot can
place, a file of another run) is skipped and counted in a note on the run (``twin.runread``);
a run dir with nothing readable at all is a one-line error.

Memory is bounded by the page, not the logs: each run is read in streamed passes and its
series decimated (min/max per bucket, ``twin.report.decimate``), and runs are read one at a
time (``twin.report.build``); ``drumtwin bench report`` measures it (docs/numbers.md).
"""

from __future__ import annotations

from twin.report.build import build_report, render_html, run_specs, time_to_mix_check, write_report
from twin.report.load import RunData, load_run

__all__ = ["RunData", "build_report", "load_run", "render_html", "run_specs", "time_to_mix_check", "write_report"]
