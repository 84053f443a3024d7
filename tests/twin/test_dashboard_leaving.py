"""A viewer that leaves while its controls are being built is not counted as a viewer with a STOP.

``Dashboard.viewers_with_estop`` is what the run reads to know an operator can stop the mill from a
browser; a closed tab counted there would claim a STOP button that nobody has.
"""

from __future__ import annotations

import pytest

import twin.dashboard.server as server_mod
from tests.twin.dashboard_fakes import RecordingControls
from tests.twin.dashboard_helpers import drain_callbacks, open_viewer, wait_for_label
from tests.waiting import wait_until
from twin.dashboard import Dashboard
from twin.dashboard.guard import close_client
from twin.state import LiveState


@pytest.mark.timeout(60)
def test_a_viewer_gone_while_its_controls_were_built_is_not_counted(monkeypatch) -> None:
    dash = Dashboard(LiveState(), RecordingControls(), port=0, update_hz=4).start()
    try:
        real_build = dash.viewers.build
        left: list[int] = []

        def build_as_it_leaves(client) -> None:  # the tab closes between the origin check and the build
            if not left:
                left.append(client.client_id)
                close_client(dash._server, client.client_id)
                wait_until(lambda: server_mod.client_headers(dash._server, client.client_id) is None, 10,
                           "the viewer's websocket to close")
            real_build(client)

        monkeypatch.setattr(dash.viewers, "build", build_as_it_leaves)
        ws = open_viewer(dash.url)
        ws.close()
        drain_callbacks(dash._server)
        assert left and dash.viewers_with_estop() == 0
        with open_viewer(dash.url) as ws2:  # a viewer that stays is counted, and uncounted when it leaves
            assert wait_for_label(ws2, "EMERGENCY STOP", 20)
            wait_until(lambda: dash.viewers_with_estop() == 1, 10, "the staying viewer counted")
        wait_until(lambda: dash.viewers_with_estop() == 0, 10, "the viewer forgotten when it left")
    finally:
        dash.stop()
