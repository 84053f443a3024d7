"""The one exception type of ``vision``: bad input or a broken environment, said in one line."""


class VisionError(ValueError):
    """A clear, user-facing error of the ``vision`` package (the CLI prints it as one line)."""
