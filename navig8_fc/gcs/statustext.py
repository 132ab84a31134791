"""STATUSTEXT building: severity, 50-byte chunks with id/chunk_seq for long texts (MAVLink 2).

A refusal reason from the parameter registry (e.g. the stability-floor text) is often longer than the 50
characters one STATUSTEXT carries. MAVLink 2 STATUSTEXT has `id` and `chunk_seq` extension fields for that:
id = 0 means "this is the only chunk"; a longer text goes out as chunks with one non-zero id and chunk_seq
0, 1, 2...; a NUL in the text marks the last chunk, so when the text is an exact multiple of 50 bytes an
empty chunk follows to terminate it. QGC and MAVProxy reassemble; older clients show the pieces.
"""

from __future__ import annotations

from typing import Any

from pymavlink.dialects.v20 import common as mavlink2

STATUSTEXT_LEN = 50

SEVERITY_WARNING = mavlink2.MAV_SEVERITY_WARNING
SEVERITY_INFO = mavlink2.MAV_SEVERITY_INFO
SEVERITY_ERROR = mavlink2.MAV_SEVERITY_ERROR


class StatusTextEncoder:
    """Builds STATUSTEXT messages; owns the rolling id for chunked texts (share one per vehicle)."""

    def __init__(self, mav: Any) -> None:
        self._mav = mav
        self._next_id = 1

    def encode(self, severity: int, text: str) -> list[Any]:
        data = text.encode("ascii", errors="replace")
        if len(data) <= STATUSTEXT_LEN:
            return [self._mav.statustext_encode(int(severity), data)]
        chunk_id = self._next_id
        self._next_id = self._next_id % 65535 + 1  # uint16, never 0
        chunks = [data[i : i + STATUSTEXT_LEN] for i in range(0, len(data), STATUSTEXT_LEN)]
        if len(chunks[-1]) == STATUSTEXT_LEN:
            chunks.append(b"")  # the terminating NUL must come somewhere
        return [self._mav.statustext_encode(int(severity), c, chunk_id, seq) for seq, c in enumerate(chunks)]

    def warning(self, text: str) -> list[Any]:
        return self.encode(SEVERITY_WARNING, text)

    def info(self, text: str) -> list[Any]:
        return self.encode(SEVERITY_INFO, text)
