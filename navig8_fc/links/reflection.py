"""A cap on what a link sends to an address it cannot vouch for (docs/security.md, "Peers, telemetry and
reflection").

Over UDP a source address is a claim: a datagram that says it comes from 10.0.0.7 may come from anyone, and what
we answer goes to 10.0.0.7. One spoofed HEARTBEAT claiming an allowed system id would make that address a peer
and send it full telemetry for good (a reflector: kilobytes a second for 21 bytes). So every address but the ones
`vouched` for (the link's configured peers; every address once signing is on, since a signed frame cannot come
from someone without the key and a replay is refused) gets at most `ratio` bytes for every byte it sent, counted
over the whole exchange: a spoofed source's victim receives at most twice what the attacker spent. A ground
station at an address nobody configured gets that much until it is configured (`--gcs-port`, `--gcs-link`) or
signing is set up.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable

Address = tuple[str, int]

REFLECTION_RATIO = 2.0  # bytes out per byte in, at most, to an address nobody vouched for
SOURCES_KEPT = 256  # addresses whose balance is kept; a forgotten one starts again from nothing (never more)


class ReflectionBudget:
    """Per-address credit: `ratio` x bytes received from it - bytes sent to it (module docstring)."""

    def __init__(self, vouched: Callable[[Address], bool], ratio: float = REFLECTION_RATIO,
                 sources_kept: int = SOURCES_KEPT) -> None:
        self._vouched = vouched
        self.ratio = float(ratio)
        self._kept = int(sources_kept)
        self._credit_bytes: OrderedDict[Address, float] = OrderedDict()

    def received(self, addr: Address, n_bytes: int) -> None:
        """A datagram of `n_bytes` arrived from `addr`."""
        if self._vouched(addr):
            return
        credit = self._credit_bytes.pop(addr, 0.0) + self.ratio * n_bytes
        self._credit_bytes[addr] = credit
        if len(self._credit_bytes) > self._kept:
            self._credit_bytes.popitem(last=False)  # the least recently heard from

    def allows(self, addr: Address, n_bytes: int) -> bool:
        """Whether `n_bytes` may go to `addr` now (then they are charged)."""
        if self._vouched(addr):
            return True
        credit = self._credit_bytes.get(addr, 0.0)
        if credit < n_bytes:
            return False
        self._credit_bytes[addr] = credit - n_bytes
        return True
