"""A run in the catalogue: registered at its start, completed at its stop, never its failure.

``drumtwin run`` (``twin.run.main``) indexes its own folder through :class:`RunIndexer` twice:
once its log exists (the catalogue shows it running, with the process that writes it) and once
it has stopped. A catalogue that cannot be reached or written (a full disk, a corrupt file, a
server that is down) costs the run nothing: a warning on stderr and a ``catalogue_unavailable``
record in its log; ``drumtwin runs list`` (or ``rebuild``) indexes the folder later.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from twin.catalogue.summary import process_identity, rig_hash

log = logging.getLogger("drumtwin.catalogue")


def rig_identity(config_path: Path | None, mixer: Mapping[str, Any] | None, classes: Any) -> dict[str, str]:
    """The rig a run is of: its config's name (the file's stem; ``demo`` without one) and a hash of
    its mixer and colour classes (``metadata.json``'s ``rig``)."""
    name = Path(config_path).stem if config_path is not None else "demo"
    return {"name": name, "hash": rig_hash(mixer, classes)}


def run_metadata(config_path: Path | None, mixer: Mapping[str, Any] | None, classes: Any) -> dict[str, Any]:
    """What the catalogue needs in ``metadata.json``: the rig, and the process writing the run
    (to tell later whether it still runs)."""
    return {"rig": rig_identity(config_path, mixer, classes), "process": process_identity()}


class RunIndexer:
    """Indexes one run folder in a catalogue; every failure is a warning and a call to
    ``on_unavailable(message)`` (the run's log), never an exception."""

    def __init__(self, url: str | None, run_dir: Path, on_unavailable: Callable[[str], None]) -> None:
        self.url = url
        self.run_dir = Path(run_dir)
        self.on_unavailable = on_unavailable
        self.id: str | None = None

    def index(self, when: str) -> bool:
        """Index the folder now (``when``: "start" or "stop", for the warning); True when it landed."""
        try:
            from twin.catalogue.store import Catalogue

            with Catalogue.open(self.url, self.run_dir.parent) as cat:
                s = cat.index_folder(self.run_dir)
            self.id = s.id if s is not None else self.id
            return True
        except Exception as exc:  # nothing the catalogue does may end the run
            first = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
            message = (f"run catalogue not updated at the run's {when} ({first}); the run goes on and its folder "
                       "is indexed by the next 'drumtwin runs list'")
            log.warning("%s", message)
            log.debug("catalogue failure", exc_info=True)
            self.on_unavailable(message)
            return False
