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
``metadata.json``) renders what was logged and says that the run did not end cleanly.
"""

from __future__ import annotations

from twin.report.build import RunData, build_report, load_run, render_html, time_to_mix_check

__all__ = ["RunData", "build_report", "load_run", "render_html", "time_to_mix_check"]
