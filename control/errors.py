"""The one exception type of ``control``: bad input or a broken environment, said in one line."""


class ControlError(ValueError):
    """A clear, user-facing error of the ``control`` package (the CLI prints it as one line)."""
