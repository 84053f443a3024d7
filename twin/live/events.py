"""Where the live workers report: the event sink (typed run records onto the run's bus, see
``twin.records``; the run log and the dashboard's state subscribe)."""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any, Protocol

from twin.records import Bus, DecisionMade, FaultCleared, FaultRaised, Record
from twin.runlog import RecordWriter, write_record
from twin.state import LiveState


class EventSink(Protocol):
    """Where workers report: typed run records (``publish``, see ``twin.records``; a
    ``FaultRaised`` goes out once until its ``FaultCleared``) and metadata for the run log's
    ``metadata.json``."""

    def publish(self, rec: Record) -> None: ...
    def metadata(self, **data: object) -> None: ...


class RunLogLike(RecordWriter, Protocol):
    """The run log as the sink uses it (``twin.runlog.RunLog``): a record writer with metadata."""

    def set_metadata(self, **data: Any) -> None: ...


class RunEvents:
    """The run's :class:`EventSink`: records go on the run's :class:`Bus` (``bus``), to which the
    run log (``twin.runlog.write_record``: CSV rows, JSONL events) and the dashboard's state
    (``LiveState.record``) subscribe. Faults go through the run's one ``ActiveFaults``
    (``state.faults``): a ``FaultRaised`` is published only when its fault is not active, a
    ``FaultCleared`` only when it is. Thread-safe; counts faults and decisions. A run-log write
    that fails (disk full, read-only) never raises into a worker: the first one is a ``run_log``
    alarm and goes to ``on_failure`` (the loop ends the run)."""

    def __init__(
        self, runlog: RunLogLike, state: LiveState, on_failure: Callable[[str], None] | None = None,
        bus: Bus | None = None,
    ) -> None:
        self.runlog = runlog
        self.state = state
        self.faults = state.faults
        self.on_failure = on_failure
        self.bus = bus if bus is not None else Bus()
        self._lock = threading.Lock()
        self.n_faults = 0
        self.n_decisions = 0
        self.log_error: str | None = None
        self.bus.subscribe(self._log)
        self.bus.subscribe(state.record)

    def _log(self, rec: Record) -> None:
        self._write(write_record, self.runlog, rec)

    def _write(self, write: Callable[..., object], *args: object, **kwargs: object) -> None:
        try:
            write(*args, **kwargs)
        except OSError as exc:
            with self._lock:
                if self.log_error is not None:
                    return
                self.log_error = reason = f"cannot write the run log: {exc}"
            self.faults.raise_fault("run_log", reason)
            if self.on_failure is not None:
                self.on_failure(reason)

    def publish(self, rec: Record) -> None:
        if isinstance(rec, FaultRaised):
            if not self.faults.raise_fault(rec.fault, rec.message, shown=False):
                return
            with self._lock:
                self.n_faults += 1
            self.bus.publish(rec)
            self.faults.show(rec.fault)  # the alarm once its event is logged
            return
        if isinstance(rec, FaultCleared) and not self.faults.clear(rec.fault):
            return
        if isinstance(rec, DecisionMade):
            with self._lock:
                self.n_decisions += 1
        self.bus.publish(rec)

    def metadata(self, **data: object) -> None:
        self._write(self.runlog.set_metadata, **data)

    def active(self) -> frozenset[str]:
        return self.faults.keys()


__all__ = ["EventSink", "RunEvents", "RunLogLike"]
