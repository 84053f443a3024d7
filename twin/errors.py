"""The exception types of ``twin``: bad run options or a broken environment, said in one line."""

EXIT_BAD_INPUT = 2
"""Exit code of bad input or a broken environment (every ``TwinError``, the CLI's usage errors)."""

EXIT_WORKER_CRASHED = 3
"""Exit code of a run that ended because one of its workers crashed or hung (a bug, not bad
input): the mill was stopped on the way out and the log holds a ``worker_crashed`` fault
(docs/safety.md)."""


class TwinError(ValueError):
    """A clear, user-facing error of the ``twin`` application (the CLI prints it as one line)."""

    exit_code: int = EXIT_BAD_INPUT


class RunFailed(TwinError):
    """A live run that had to end (``twin.run.loop.LiveLoop.failure``); ``exit_code`` says why:
    :data:`EXIT_BAD_INPUT` (its inputs or environment: a full disk, no drum in the frames) or
    :data:`EXIT_WORKER_CRASHED`."""

    def __init__(self, message: str, exit_code: int = EXIT_BAD_INPUT) -> None:
        super().__init__(message)
        self.exit_code = exit_code
