"""The Foxglove WebSocket refuses foreign browser origins (docs/foxglove.md, "Who may connect"): a page from another
site open in the operator's browser gets `403 Forbidden` at the handshake, while Foxglove's web app, a client that
sends no Origin (the `websockets` library, as navig8-sitl's live test connects) and an origin the operator allowed
get the server's advertisements."""

from __future__ import annotations

import json

import pytest
from websockets.exceptions import InvalidStatus
from websockets.sync.client import connect

from navig8_fc.shell.foxglove_out import LiveServer

FOXGLOVE_SUBPROTOCOL = "foxglove.sdk.v1"


def _advertises(port: int, origin: str | None) -> bool:
    """Whether a client with this Origin completes the handshake and hears the channels advertised."""
    with connect(f"ws://127.0.0.1:{port}", subprotocols=[FOXGLOVE_SUBPROTOCOL], open_timeout=10,
                 origin=origin) as ws:  # type: ignore[arg-type]
        assert ws.subprotocol == FOXGLOVE_SUBPROTOCOL
        for _ in range(10):
            msg = ws.recv(timeout=5.0)
            if isinstance(msg, str) and json.loads(msg)["op"] == "advertise":
                return True
    return False


def test_a_foreign_browser_origin_is_refused_and_foxglove_and_allowed_origins_pass() -> None:
    server = LiveServer("127.0.0.1", 0, "origin test")
    try:
        with pytest.raises(InvalidStatus) as refused:
            _advertises(server.port, "https://evil.example")
        assert refused.value.response.status_code == 403
        with pytest.raises(InvalidStatus):
            _advertises(server.port, "null")  # a sandboxed frame or a file:// page
        assert _advertises(server.port, "https://app.foxglove.dev")
        assert _advertises(server.port, None)
        assert server.gate.n_refused == 2
    finally:
        server.close()
    allowing = LiveServer("127.0.0.1", 0, "origin test", {"http://localhost:3000"})
    try:
        assert _advertises(allowing.port, "http://localhost:3000")
        with pytest.raises(InvalidStatus):
            _advertises(allowing.port, "https://evil.example")
    finally:
        allowing.close()
