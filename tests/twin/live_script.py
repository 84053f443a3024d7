"""One way to drive a whole-loop test: ``run_scripted(cfg, body)`` runs the loop and, once it
has started, ``body(loop, plant)`` in a thread of its own (inject faults, wait, record into the
test's own dict); the run ends when the body returns, and an exception in the body (a failed
wait, an assertion) is raised in the test after the loop has shut down."""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import replace
from typing import Any

from twin.run.main import run_live
from twin.run.settings import Seams


def run_scripted(cfg: Any, body: Callable[[Any, Any], None],
                 before: Callable[[Any, Any], None] | None = None, seams: Seams | None = None) -> None:
    """Run ``cfg`` (a resolved ``RunConfig``) with ``body(loop, plant)`` beside it; ``before(loop,
    plant)`` runs first in the loop's start-up thread (e.g. to wrap a box before the body reads it);
    ``seams``: the run's test seams (``twin.run.settings.Seams``)."""
    failure: list[BaseException] = []

    def on_started(loop: Any, plant: Any, dash: Any) -> None:
        if before is not None:
            before(loop, plant)

        def run() -> None:
            try:
                body(loop, plant)
            except BaseException as exc:
                failure.append(exc)
            finally:
                loop.stop_event.set()

        threading.Thread(target=run, daemon=True).start()

    run_live(cfg, replace(seams or Seams(), on_started=on_started))
    if failure:
        raise failure[0]
