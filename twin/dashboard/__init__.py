"""The viser dashboard of the live loop (see ``server.Dashboard``)."""

from twin.dashboard.server import Dashboard, alarms_html, axis_range, numbers_markdown, parse_rpm_list

__all__ = ["Dashboard", "alarms_html", "axis_range", "numbers_markdown", "parse_rpm_list"]
