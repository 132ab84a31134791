"""The Foxglove WebSocket's origin check (navig8_fc.shell.origin_gate): the Origin header read from a request head,
and which origins pass."""

from __future__ import annotations

from navig8_fc.shell.origin_gate import DEFAULT_ALLOWED_ORIGINS, origin_allowed, request_origin

HEAD = (b"GET / HTTP/1.1\r\nHost: 127.0.0.1:8765\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
        b"ORIGIN:  https://evil.example \r\nSec-WebSocket-Protocol: foxglove.sdk.v1\r\n\r\n")


def test_the_origin_header_is_read_case_insensitively_and_may_be_absent() -> None:
    assert request_origin(HEAD) == "https://evil.example"
    assert request_origin(HEAD.replace(b"ORIGIN:  https://evil.example \r\n", b"")) is None
    assert request_origin(b"GET /origin: x HTTP/1.1\r\n\r\n") is None  # the request line is not a header


def test_which_origins_pass() -> None:
    assert origin_allowed(None, DEFAULT_ALLOWED_ORIGINS)  # not a browser page
    assert origin_allowed("https://app.foxglove.dev", DEFAULT_ALLOWED_ORIGINS)
    assert origin_allowed("HTTPS://APP.FOXGLOVE.DEV/", DEFAULT_ALLOWED_ORIGINS)
    for foreign in ("https://evil.example", "null", "https://app.foxglove.dev.evil.example", "http://app.foxglove.dev"):
        assert not origin_allowed(foreign, DEFAULT_ALLOWED_ORIGINS), foreign
    assert origin_allowed("http://localhost:3000", {"http://localhost:3000"})
    assert origin_allowed("https://anything.example", {"*"})
