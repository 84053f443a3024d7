"""The one exception type of ``sim``: bad input or a broken environment, said in one line."""


class SimError(ValueError):
    """A clear, user-facing error of the ``sim`` package (the CLI prints it as one line)."""
