"""The one exception type of ``twin``: bad run options or a broken environment, said in one line."""


class TwinError(ValueError):
    """A clear, user-facing error of the ``twin`` application (the CLI prints it as one line)."""
