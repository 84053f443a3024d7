"""``python -m twin.records`` prints the docs' table of record kinds."""

from twin.records import records_table

print(records_table(), end="")
