"""Physics -> frames: the 2D pymunk drum twin, renderer, calibration, what-if studies.

Imports ``vision`` (to measure its own frames) and nothing else of drumtwin.
"""
