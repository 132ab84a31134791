"""MAVFTP replies paced per source: a token bucket of bytes per second for each place replies go, so that what one
source can draw from the vehicle stays bounded whatever it asks (a BurstReadFile answers a 19-byte request with the
whole file), and a cap on the packets sent per service poll, so that a flood is worked off between control steps.

- Every reply costs its MAVLink 2 frame size (10-byte header, the payload without its trailing zeros, 2-byte CRC:
  what goes on the wire unsigned). A source's bucket holds at most `burst_bytes` and refills at `bytes_per_s`.
- Single replies (ACK/NAK to OpenFileRO, ReadFile, ...) go at once while the bucket holds their cost, else they
  wait in the source's queue (at most `pending_max`; beyond that the oldest is dropped: the client asks again).
- A BurstReadFile's packets are drawn one at a time as the bucket refills, over as many polls as it takes; a new
  BurstReadFile on the same session replaces the one still running (the client restarted it), so repeating the
  request does not multiply the output.
- At most `packets_per_poll` packets leave per poll, over all sources (round robin).

Pure: the caller gives the time (wall seconds) and sends what comes back. The replies are MAVFTP payloads by
default; another service (the log download, navig8_fc.gcs.log_transfer) paces its own messages with its own `cost`.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Hashable, Iterator
from dataclasses import dataclass, field
from typing import Any

FRAME_OVERHEAD_BYTES = 12  # MAVLink 2 header (10) + CRC (2)
TARGET_FIELDS_BYTES = 3  # FILE_TRANSFER_PROTOCOL's target_network, target_system, target_component


@dataclass(frozen=True)
class ReplyBudget:
    """How much MAVFTP one source may draw (module docstring; docs/security.md, "MAVFTP"). The defaults are for a
    source the FC cannot vouch for; OPERATOR_BUDGET for the operator's configured station."""

    bytes_per_s: float = 2500.0  # a 41 KB file in ~17 s; a 100 requests/s flood of 19-byte requests gets < 2x back
    burst_bytes: float = 1500.0  # about five full packets at once
    packets_per_poll: int = 4  # the service polls every ~1 ms between control steps
    pending_max: int = 8  # single replies waiting for the bucket, per source


# The operator's configured station (GcsService's OperatorSources: where the operator pointed the link, or a TCP
# connection) is no amplifier for anyone else: its downloads go at a ground station's pace (QGroundControl's 62 kB
# parameter metadata in ~1.5 s instead of ~25 s); the packets per poll still bound the work between control steps.
OPERATOR_BUDGET = ReplyBudget(bytes_per_s=50_000.0, burst_bytes=6_000.0)


def frame_bytes(payload: bytes) -> int:
    """The unsigned MAVLink 2 frame size of a FILE_TRANSFER_PROTOCOL carrying `payload` (trailing zeros cut)."""
    return FRAME_OVERHEAD_BYTES + TARGET_FIELDS_BYTES + len(payload.rstrip(b"\0"))


@dataclass
class _Source:
    """One destination's bucket and what waits for it; `to` is the requester (system id, component id)."""

    to: tuple[int, int]
    tokens: float
    t_s: float
    budget: ReplyBudget
    replies: deque[bytes] = field(default_factory=deque)
    bursts: dict[int, Iterator[bytes]] = field(default_factory=dict)  # session -> its remaining packets
    head: bytes | None = None  # a burst packet drawn but not yet affordable
    head_session: int = -1


class ReplyPacer:
    """Per-source token buckets over MAVFTP replies (module docstring)."""

    def __init__(self, budget: ReplyBudget = ReplyBudget(), operator: Callable[[Hashable], bool] | None = None,
                 operator_budget: ReplyBudget = OPERATOR_BUDGET, cost: Callable[[Any], int] = frame_bytes) -> None:
        """operator(key): whether replies to `key` go to the operator's configured station (its own budget);
        cost(reply): the bytes a reply puts on the wire (MAVFTP payloads: `frame_bytes`)."""
        self.budget = budget
        self._cost = cost
        self._operator, self._operator_budget = operator, operator_budget
        self._sources: dict[Hashable, _Source] = {}
        self.n_dropped = 0  # single replies dropped because a source's queue was full

    @property
    def pending(self) -> bool:
        return any(s.replies or s.bursts or s.head is not None for s in self._sources.values())

    def add(self, key: Hashable, to: tuple[int, int], now_s: float, replies: list[bytes],
            burst: Iterator[bytes] | None = None, session: int = 0) -> None:
        """Queue a request's answer for `key` (where the replies go), addressed to `to`."""
        src = self._sources.get(key)
        if src is None:
            budget = (self._operator_budget if self._operator is not None and self._operator(key)
                      else self.budget)
            src = self._sources[key] = _Source(to, budget.burst_bytes, now_s, budget)
        src.to = to
        for r in replies:
            if len(src.replies) >= src.budget.pending_max:
                src.replies.popleft()
                self.n_dropped += 1
            src.replies.append(r)
        if burst is not None:
            src.bursts.pop(session, None)
            src.bursts[session] = burst
            if src.head_session == session:
                src.head = None  # the packet drawn belonged to the burst this one replaces

    def take(self, now_s: float, only: Hashable = None, limit: int | None = None
             ) -> list[tuple[Hashable, tuple[int, int], bytes]]:
        """The replies the buckets afford now, (key, requester, payload); `only`: one source's alone."""
        left = self.budget.packets_per_poll if limit is None else limit
        out: list[tuple[Hashable, tuple[int, int], bytes]] = []
        keys = [only] if only is not None else list(self._sources)
        for key in keys:
            src = self._sources.get(key)
            if src is None:
                continue
            budget = src.budget
            src.tokens = min(budget.burst_bytes, src.tokens + (now_s - src.t_s) * budget.bytes_per_s)
            src.t_s = now_s
            while left > 0:
                drawn = self._next(src)
                if drawn is None:
                    break
                payload, session = drawn
                cost = self._cost(payload)
                if cost > src.tokens:
                    if session < 0:
                        src.replies.appendleft(payload)
                    else:
                        src.head, src.head_session = payload, session
                    break
                src.tokens -= cost
                out.append((key, src.to, payload))
                left -= 1
            if not (src.replies or src.bursts or src.head is not None) and src.tokens >= budget.burst_bytes:
                del self._sources[key]  # nothing owed and a full bucket: forget the source
        return out

    @staticmethod
    def _next(src: _Source) -> tuple[bytes, int] | None:
        """The next payload owed and its burst's session (-1: a single reply)."""
        if src.replies:
            return src.replies.popleft(), -1
        if src.head is not None:
            head, src.head = src.head, None
            return head, src.head_session
        while src.bursts:
            session = next(iter(src.bursts))
            payload = next(src.bursts[session], None)
            if payload is not None:
                return payload, session
            del src.bursts[session]
        return None


__all__ = ["OPERATOR_BUDGET", "ReplyBudget", "ReplyPacer", "frame_bytes"]
