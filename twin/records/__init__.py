"""What a run emits: one stream of typed, immutable run records, and the bus that carries them.

Every record is a frozen dataclass with a run time ``t_s`` and a ``kind``. Each kind declares
its fields and their units once, in this package; everything else is derived from these classes:

* the frame CSV's columns (:data:`FRAME_COLUMNS`, from :class:`FrameReading`) and the
  dashboard's plot series (:data:`SERIES`, the fields marked ``plot``);
* the ``events.jsonl`` lines: ``{"t_s", "wall_s", "kind", **fields}`` of every record whose
  class is ``logged`` (:func:`event_fields`; optional fields that are None are left out);
* the dashboard's numbers panel (``twin.state.Panel``), which folds the records it sees;
* the table of record kinds in ``docs/architecture.md`` (:func:`records_table`, checked by a test);
* the run log's descriptors (units, dtype, source of each column and field: ``twin.descriptors``)

Producers (the live workers, the loop, the dashboard) construct these classes and ``publish``
them (``twin.live.events.EventSink``; no producer names a kind by string, so a misspelt kind
or field is a mypy error) onto a :class:`Bus`; consumers subscribe: the run log
(``twin.runlog.RunLog.record``: CSV rows and JSONL lines), the dashboard's state
(``twin.state.LiveState.record``: plots, numbers panel). The one set of active faults is
:class:`ActiveFaults` (the sink publishes a :class:`FaultRaised` only when its fault is not
active). ``compare``, ``report`` and the tests read the same records back with
``twin.runlog.read_frames`` / ``read_events`` (dicts, the JSONL keys) or ``read_records``
(typed: the one name -> class lookup, :func:`record_of`).

The modules (import from ``twin.records``): ``declare`` (:func:`unit`, :func:`opt`,
:class:`Record`, :func:`register`, :data:`KINDS`, the JSONL side: :func:`record_of`,
:func:`event_fields`), ``frame`` (:class:`FrameReading`, :data:`FRAME_COLUMNS`, :data:`SERIES`),
``kinds`` (every other kind, by concern), ``bus`` (:class:`Bus`, :class:`ActiveFaults`) and
``table`` (:func:`records_table`; ``python -m twin.records`` prints it).

Adding a record kind is one declaration: a frozen dataclass in ``kinds`` under its concern,
derived from :class:`Record` (or a group base), with a ``kind`` ClassVar, its fields with
:func:`unit` / :func:`opt`, and ``@register``; then its name below, and the docs table is
regenerated with ``python -m twin.records``.
"""

from __future__ import annotations

from twin.records.bus import ActiveFaults, Bus, Subscriber
from twin.records.declare import (
    KINDS,
    Record,
    UntypedEvent,
    event_fields,
    fields_of,
    kind_of,
    opt,
    record_of,
    register,
    unit,
)
from twin.records.frame import FRAME_COLUMNS, SERIES, FrameReading  # registered first: the frame is KINDS' first kind

# isort: off
# The kinds by concern, in the registry's order (kinds.py's).
from twin.records.kinds import (
    RunStart, RunStop, FaultRaised, FaultCleared,  # the run, its faults
    OperatorAction, OperatorRejected, OperatorClamped, DecisionMade,  # the operator, the supervisor
    MillCommandSent, MillCommandDropped, MillRefused, MillMismatch, MillChangedElsewhere, MillSynced,  # the mill
    TrendSettled, TrendUnsettled, Mixed, Unmixed,  # the trend, the batch endpoint
    CatalogueUnavailable, SlowerThanGolden,  # the run catalogue, the golden batch
    TwinLag, TwinSeeded, CalibrationWaiting, CalibrationStarted, Calibrated,  # the twin
    WhatIfResult, WhatIfError, WhatIfCancelled,  # the what-if studies
    DashboardEvent, DashboardRefused, DashboardUnlockLimited, DashboardUnlockFailed, DashboardUnlocked,
    DashboardBadMessage,  # the dashboard's security events
    CameraRate, MillState, ModeSet, TwinStatus, TwinReading,  # the dashboard-only status
)
# isort: on
from twin.records.table import records_table

__all__ = [  # the package's names, what ``from twin.records import X`` gives
    "FRAME_COLUMNS", "KINDS", "SERIES", "ActiveFaults", "Bus", "Calibrated", "CalibrationStarted",
    "CalibrationWaiting", "CameraRate", "CatalogueUnavailable", "DashboardBadMessage", "DashboardEvent",
    "DashboardRefused", "DashboardUnlockFailed", "DashboardUnlockLimited", "DashboardUnlocked", "DecisionMade",
    "FaultCleared", "FaultRaised", "FrameReading", "MillChangedElsewhere", "MillCommandDropped", "MillCommandSent",
    "MillMismatch", "MillRefused", "MillState", "MillSynced", "Mixed", "ModeSet", "OperatorAction",
    "OperatorClamped", "OperatorRejected", "Record", "RunStart", "RunStop", "SlowerThanGolden", "Subscriber",
    "TrendSettled", "TrendUnsettled", "TwinLag", "TwinReading", "TwinSeeded", "TwinStatus", "Unmixed",
    "UntypedEvent", "WhatIfCancelled", "WhatIfError", "WhatIfResult", "event_fields", "fields_of", "kind_of", "opt",
    "record_of", "records_table", "register", "unit",
]
