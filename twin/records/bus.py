"""The run's record bus (publish/subscribe) and the one set of active faults."""

from __future__ import annotations

import threading
from collections.abc import Callable

from twin.records.declare import Record

Subscriber = Callable[[Record], None]


class Bus:
    """Publish/subscribe of run records: ``publish`` hands each record to every subscriber in
    the order they subscribed, synchronously on the publisher's thread (subscribers are
    thread-safe and quick: a lock and an append)."""

    def __init__(self) -> None:
        self._subs: tuple[Subscriber, ...] = ()
        self._lock = threading.Lock()

    def subscribe(self, fn: Subscriber) -> None:
        with self._lock:
            self._subs = (*self._subs, fn)

    def publish(self, rec: Record) -> None:
        for fn in self._subs:
            fn(rec)


# -- the one set of active faults -------------------------------------------------------------
class ActiveFaults:
    """The run's active faults, key -> message (the one place they are kept): the event sink
    raises a fault only when it is not active and clears it only when it is; the dashboard
    shows the messages as alarms. A fault raised with ``shown=False`` is active at once but
    shown only from :meth:`show` on (the sink shows it once its event is logged, as the run
    always did). Thread-safe."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._active: dict[str, tuple[str, bool]] = {}  # key -> (message, shown)

    def raise_fault(self, key: str, message: str, shown: bool = True) -> bool:
        """True when ``key`` was not active (it is now)."""
        with self._lock:
            if key in self._active:
                return False
            self._active[key] = (message, shown)
            return True

    def show(self, key: str) -> None:
        """Show an active fault raised with ``shown=False``."""
        with self._lock:
            if key in self._active:
                self._active[key] = (self._active[key][0], True)

    def clear(self, key: str) -> bool:
        """True when ``key`` was active (it is not now)."""
        with self._lock:
            return self._active.pop(key, None) is not None

    def keys(self) -> frozenset[str]:
        with self._lock:
            return frozenset(self._active)

    def messages(self) -> tuple[str, ...]:
        with self._lock:
            return tuple(m for m, shown in self._active.values() if shown)
