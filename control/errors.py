"""The one exception type of ``control``: bad input or a broken environment, said in one line."""


class ControlError(ValueError):
    """A clear, user-facing error of the ``control`` package (the CLI prints it as one line)."""


class MillRefused(ControlError):
    """The motor board answered a command with ``NAK`` and a reason: the link is fine, the
    command was not applied. Not a lost link: the caller logs it and drops the command."""

    def __init__(self, command: str, reason: str) -> None:
        super().__init__(f"mill refused {command}: NAK {reason}")
        self.command = command
        self.reason = reason
