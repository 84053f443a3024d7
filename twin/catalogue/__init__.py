"""The run catalogue: every run folder indexed in SQLite or PostgreSQL (``drumtwin runs``)."""
