"""drumtwin application: the live loop, run logs, dashboard and CLI.

Imports flow one way: ``twin -> sim, vision, control``.
"""
