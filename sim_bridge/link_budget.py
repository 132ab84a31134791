"""The byte budget of the bridge ⇄ FC link: what one lockstep step puts on the wire, against what a serial line
carries (docs/hil.md, "Bandwidth").

Worst case per step (MAVLink 2, signed with the session key as every frame is once paired: 13 bytes more per frame;
trailing-zero truncation only ever makes frames shorter): the bundle's
five frames bridge → FC, the answer (and, at most once per step, an arm command) FC → bridge. A UART is full
duplex, so each direction is checked on its own against HEADROOM × baud / 10 (8N1: ten bits per byte); the
headroom leaves room for the 1 Hz NAVIG8_SIM_STATUS, the FC's announcements and the gaps a real UART leaves
between bytes. Network links (UDP, TCP) are reported, never refused: at these rates they are not the limit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from navig8_fc.links.transport import Connection, serial_budget
from navig8_fc.mavlink.codec import SIGNATURE_LEN, V2_OVERHEAD, Codec

HEADROOM = 0.9  # share of a serial line's bytes/s the per-step traffic may use
BUNDLE = ("ODOMETRY", "NAVIG8_ACTUATOR_STATE", "NAVIG8_ARM_STATE", "NAVIG8_TRUTH", "HIL_SENSOR")  # seam.encode_bundle
ANSWER = ("HIL_ACTUATOR_CONTROLS", "NAVIG8_ARM_CMD")


@dataclass(frozen=True)
class LinkBudget:
    bundle_bytes: int  # bridge -> FC per step, worst case
    answer_bytes: int  # FC -> bridge per step, worst case
    rate_hz: float
    capacity_bytes_s: float | None  # HEADROOM x baud / 10 for a serial line, None for UDP/TCP

    @property
    def bundle_bytes_s(self) -> float:
        return self.bundle_bytes * self.rate_hz

    def line(self) -> str:
        need = (f"{self.bundle_bytes} B/step x {self.rate_hz:g} Hz = {self.bundle_bytes_s / 1000:.1f} kB/s to the FC, "
                f"{self.answer_bytes * self.rate_hz / 1000:.1f} kB/s back")
        if self.capacity_bytes_s is None:
            return f"link budget {need}"
        return f"link budget {need}, serial allows {self.capacity_bytes_s / 1000:.1f} kB/s each way"


def frames_bytes(codec: Codec, names: tuple[str, ...]) -> int:
    """Bytes of one full-length signed frame of each message."""
    return sum(V2_OVERHEAD + SIGNATURE_LEN + codec.specs[n].size for n in names)


def link_budget(codec: Codec, conn: Connection, rate_hz: float) -> LinkBudget:
    """The budget of `conn` at `rate_hz` steps per second; ValueError (naming the numbers and the way out) when a
    serial line cannot carry it."""
    b = LinkBudget(frames_bytes(codec, BUNDLE), frames_bytes(codec, ANSWER), rate_hz, None)
    if conn.scheme != "serial":
        return b
    need, cap = serial_budget(b.bundle_bytes, rate_hz, conn, HEADROOM)
    b = LinkBudget(b.bundle_bytes, b.answer_bytes, rate_hz, cap)
    worst = max(need, b.answer_bytes * rate_hz)
    if worst > cap:
        max_hz = math.floor(cap / max(b.bundle_bytes, b.answer_bytes))  # the highest whole rate that fits
        raise ValueError(f"--link {conn.text}: {b.line()}: does not fit; lower the rate (--dt, INDI_RATE_HZ) to at "
                         f"most {max_hz} Hz or raise the baud rate")
    return b


__all__ = ["HEADROOM", "LinkBudget", "frames_bytes", "link_budget"]
