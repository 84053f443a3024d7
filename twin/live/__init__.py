"""The live loop's workers (camera, process, mill, twin, what-if, supervisor) and what they
exchange: ``snapshots`` (what they read of each other), ``commands`` (what they are told),
``events`` (where they report), ``faults`` (where a test may break them).
``twin.run.loop.LiveLoop`` is their composition root: the only place that starts and joins
their threads."""
