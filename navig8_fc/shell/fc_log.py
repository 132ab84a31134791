"""The flight-controller process's log (docs/logs.md): every datagram on every link (raw, queued and written after
the step's answer has gone out), the decoded GCS and sim-link messages, and the per-step records (/truth,
/analysis/eig, /fc/status, /fc/setpoint, /fc/command) with the Foxglove 3D channels; events, STATUSTEXT, parameter
changes and the stability record. Logging never ends the flight: an exception is counted, reported once and
logging stops; a logger that lost its file (disk full) drops and counts by itself.

The ground-station links' datagrams are logged within a budget (`GcsLogBudget`): a flood cannot fill the log, and a
datagram over the budget is left out with its decoded records and summarised once a second on
/mavlink/<link>/<direction>/over_budget (docs/logs.md, "Floods")."""

from __future__ import annotations

import dataclasses
import sys
import time
from collections.abc import Callable
from typing import Any

from navig8_fc.core import vehicle as vm
from navig8_fc.core.controller import ActuatorCommand, ControllerStatus, FcSensors
from navig8_fc.core.outer_loop import Setpoint
from navig8_fc.logrecords import (
    dialect_json_schema,
    mavlink_json_schema,
    mavlink_record_json,
)
from navig8_fc.mavlink import seam
from navig8_fc.mavlink.seam import TruthFloats
from navig8_fc.params.registry import StabilityStatus
from navig8_fc.shell.foxglove_out import FoxgloveOutput
from navig8_fc.shell.step_log import StepLog

GCS_LOG_BYTES_PER_S = 32_000.0  # raw bytes a second per GCS link and direction (a hover's telemetry: ~4.4 KB/s)
GCS_LOG_BURST_BYTES = 320_000.0  # ten seconds of it at once
OVER_BUDGET_PERIOD_NS = 1_000_000_000
OVER_BUDGET_PEERS = 8  # the busiest senders named in a summary


class GcsLogBudget:
    """A token bucket of raw bytes per (link, direction), on the wall clock; what it leaves out is counted per peer
    and handed back once a period as a summary record."""

    def __init__(self, bytes_per_s: float = GCS_LOG_BYTES_PER_S, burst_bytes: float = GCS_LOG_BURST_BYTES) -> None:
        self.bytes_per_s, self.burst_bytes = bytes_per_s, burst_bytes
        self._tokens: dict[tuple[str, str], tuple[float, int]] = {}  # key -> (tokens, wall ns of the refill)
        self._left_out: dict[tuple[str, str], dict[str, list[int]]] = {}  # key -> peer -> [datagrams, bytes]
        self._summary_due_ns = 0
        self.n_left_out = 0

    def admit(self, key: tuple[str, str], n_bytes: int, peer: str, wall_ns: int) -> bool:
        tokens, t_ns = self._tokens.get(key, (self.burst_bytes, wall_ns))
        tokens = min(self.burst_bytes, tokens + (wall_ns - t_ns) * 1e-9 * self.bytes_per_s)
        ok = n_bytes <= tokens
        self._tokens[key] = (tokens - n_bytes if ok else tokens, wall_ns)
        if not ok:
            self.n_left_out += 1
            peers = self._left_out.setdefault(key, {})
            if peer in peers or len(peers) < 4 * OVER_BUDGET_PEERS:
                count = peers.setdefault(peer, [0, 0])
                count[0] += 1
                count[1] += n_bytes
        return ok

    def summaries(self, wall_ns: int, force: bool = False) -> list[tuple[str, dict[str, Any]]]:
        """(topic, record) of what was left out since the last summary, once a period (or now when forced)."""
        if not self._left_out or (wall_ns < self._summary_due_ns and not force):
            return []
        self._summary_due_ns = wall_ns + OVER_BUDGET_PERIOD_NS
        out = []
        for (link, direction), peers in self._left_out.items():
            busiest = sorted(peers.items(), key=lambda kv: -kv[1][1])[:OVER_BUDGET_PEERS]
            out.append((f"/mavlink/{link}/{direction}/over_budget", {
                "datagrams": sum(c[0] for c in peers.values()), "bytes": sum(c[1] for c in peers.values()),
                "budget_bytes_per_s": self.bytes_per_s,
                "peers": [{"peer": p, "datagrams": c[0], "bytes": c[1]} for p, c in busiest]}))
        self._left_out = {}
        return out


@dataclasses.dataclass(frozen=True)
class StepRecord:
    """What one control step leaves for the log (written after its answer went out)."""

    t_us: int
    truth: TruthFloats | None  # the bundle's NAVIG8_TRUTH (None from a board)
    status: ControllerStatus
    command: ActuatorCommand
    setpoint: Setpoint
    wire: dict[str, Any] | None  # the bundle's messages (codec.Message records)
    answer: bytes | None  # the step's answer frame
    sensors: FcSensors | None  # the controller's input


class FcLog:
    """The MCAP log and the Foxglove output of one FC process, on the sim time `sim_ns()` gives."""

    def __init__(self, logger: Any, open_error: str | None, fox: FoxgloveOutput | None, model: vm.UamModel,
                 sim_ns: Callable[[], int]) -> None:
        self.logger = logger
        self.open_error = open_error  # why the log could not be opened (the FC flies without one)
        self.fox = fox
        self._steps = StepLog(logger, fox, model)  # the per-step records, as navig8-sim writes them
        self._sim_ns = sim_ns
        self.n_errors = 0  # exceptions while logging (contained: reported, never an exit)
        self.fail_reported = False
        # (topic, raw datagram or decoded message, peer for a datagram / None for a message, sim ns, wall ns)
        self._frame_queue: list[tuple[str, Any, str | None, int, int]] = []
        self._sim_channels: dict[tuple[str, str], int] = {}
        self._raw_topics: dict[tuple[str, str], str] = {}  # (link, direction) -> /mavlink/<link>/<direction>
        self.gcs_budget = GcsLogBudget()
        self._left_out: set[tuple[str, str]] = set()  # (link, direction) whose last datagram was left out

    @property
    def active(self) -> bool:
        """A log or a live Foxglove view wants the step records."""
        return bool(self.logger or self.fox)

    # --- link frames -------------------------------------------------------------------------------
    def datagram(self, link: str, direction: str, raw: bytes, peer: str) -> None:
        """Queue a datagram (raw, as it crossed the link); `flush_frames` writes the queue after the step's answer
        has gone out, so logging overlaps with the bridge's physics step instead of delaying the lockstep round
        trip."""
        if self.logger:
            key = (link, direction)
            topic = self._raw_topics.get(key)
            if topic is None:
                topic = self._raw_topics[key] = f"/mavlink/{link}/{direction}"
            wall_ns = time.time_ns()
            if link != "sim":  # the sim link is the flight's record: never left out
                if not self.gcs_budget.admit(key, len(raw), peer, wall_ns):
                    self._left_out.add(key)
                    return
                self._left_out.discard(key)
                for summary_topic, rec in self.gcs_budget.summaries(wall_ns):
                    self._frame_queue.append((summary_topic, rec, None, self._sim_ns(), wall_ns))
            self._frame_queue.append((topic, raw, peer, self._sim_ns(), wall_ns))

    def decoded(self, link: str, direction: str, raw: bytes, msg: Any, peer: tuple[str, int]) -> None:
        """Queue a decoded GCS/API message for its /mavlink/<link>/<dir>/<TYPE> channel."""
        if self.logger and (link, direction) not in self._left_out:  # its datagram was logged
            self._frame_queue.append((f"/mavlink/{link}/{direction}/{msg.get_type()}", msg, None, self._sim_ns(),
                                      time.time_ns()))

    def flush_frames(self) -> None:
        q, self._frame_queue = self._frame_queue, []
        if not self.logger:
            return
        for topic, item, peer, t_ns, wall_ns in q:
            if peer is not None:  # a raw datagram
                self.logger.log_raw(topic, t_ns, item, publish_ns=wall_ns, peer=peer)
            elif type(item) is dict:  # an over_budget summary
                self.logger.log(topic, t_ns, item, publish_ns=wall_ns)
            else:  # a decoded GCS message (pymavlink)
                self.logger.log(topic, t_ns, item.to_dict(), publish_ns=wall_ns, schema=mavlink_json_schema(type(item)))

    # --- the step ----------------------------------------------------------------------------------
    def _sim_channel(self, direction: str, name: str) -> int:
        """The decoded /mavlink/sim/<direction>/<NAME> channel (schema from the message definition)."""
        cid = self._sim_channels.get((direction, name))
        if cid is None:
            assert self.logger is not None
            cid = self._sim_channels[(direction, name)] = self.logger.json_channel(
                f"/mavlink/sim/{direction}/{name}", dialect_json_schema(name))
        return cid

    def _tick(self, r: StepRecord, sim_codec: Any, lam_min: float, lam_crit: float) -> None:
        t_ns = seam.sim_us_from_time_usec(r.t_us) * 1000
        w = time.time_ns()
        lg = self.logger
        if lg is not None:
            # The sim link decoded, as the GCS links are: the FC's raw sensor inputs and its answer, plottable.
            # NAVIG8_TRUTH's decoded form is /truth. Lean path: channel ids cached, orjson straight to the writer.
            if r.wire:
                for name, m in r.wire.items():  # codec.Message records (BundleAssembler.completed)
                    if name != "NAVIG8_TRUTH":
                        lg.log_json_bytes(self._sim_channel("in", name), t_ns, mavlink_record_json(m), w)
            if r.answer is not None:
                got = sim_codec.decode_frame(r.answer) if sim_codec is not None else None
                if got is not None:
                    lg.log_json_bytes(self._sim_channel("out", got.name), t_ns, mavlink_record_json(got), w)
        self._steps.tick(t_ns, r.truth, r.sensors, r.status, r.command, r.setpoint, lam_min, lam_crit, w)

    def finish(self) -> None:
        """The last step's held setpoint (StepLog.finish), before the log closes."""
        try:
            self._steps.finish(time.time_ns())
        except Exception:  # noqa: BLE001 - logging must never end the flight
            self.n_errors += 1

    def step(self, record: StepRecord | None, sim_codec: Any = None, lam_min: float = 0.0, lam_crit: float = 0.0
             ) -> str | None:
        """Log a step's records, or the queued datagrams (None). Contained: an exception here is counted and logging
        stops. Returns the STATUSTEXT to send when logging has just stopped (once), else None."""
        try:
            if record is not None:
                self._tick(record, sim_codec, lam_min, lam_crit)
                if self.logger is not None:
                    self.logger.maybe_rotate()  # once per step: the size check is a syscall
            else:
                self.flush_frames()
        except Exception as e:  # noqa: BLE001 - logging must never end the flight
            self.n_errors += 1
            self._frame_queue.clear()
            if self.logger is not None:
                self.logger.fail(f"{type(e).__name__}: {e}")
        lg = self.logger
        if lg is not None and lg.error is not None and not self.fail_reported:
            self.fail_reported = True
            print(f"navig8-fc: logging stopped ({lg.error}); records from now on are dropped and counted",
                  file=sys.stderr)
            return f"Log stopped: {lg.error}"
        return None

    # --- records -------------------------------------------------------------------------------------
    def record(self, topic: str, data: Any) -> None:
        """One record on the current sim time, published now (/fc/event, /fc/statustext, /fc/param_change...)."""
        if self.logger:
            self.logger.log(topic, self._sim_ns(), data, publish_ns=time.time_ns())

    def record_contained(self, topic: str, data: Any) -> None:
        """`record`, an exception counted and reported to the logger (the once-a-second /fc/sim_guard record)."""
        if self.logger is not None:
            try:
                self.record(topic, data)
            except Exception as e:  # noqa: BLE001 - logging must never end the flight
                self.n_errors += 1
                self.logger.fail(f"{type(e).__name__}: {e}")

    def stability(self, stab: StabilityStatus) -> None:
        """/fc/stability: lambda_crit, the guaranteed min eigenvalue and the margin of the configuration in force
        (LAM_CRIT, LAM_MARGIN), once at start and again whenever a parameter they depend on changes them."""
        self.record("/fc/stability", {**dataclasses.asdict(stab), "meets_margin": stab.meets_margin})

    def statustext(self, text: str, severity: int) -> None:
        self.record("/fc/statustext", {"severity": severity, "text": text})

    def stats(self) -> dict[str, Any]:
        lg = self.logger
        return {"log_errors": self.n_errors, "log_dropped": lg.dropped if lg is not None else 0,
                "log_gcs_over_budget": self.gcs_budget.n_left_out,
                "log_rotations": lg.rotations if lg else 0,
                "log_error": (lg.error if lg is not None else self.open_error)}

    def close(self, metadata: dict[str, Any]) -> None:
        """Write the closing metadata (name -> record, in order) and close the log and the Foxglove output."""
        lg = self.logger
        if lg and lg.error is not None:
            print(f"navig8-fc: log {lg.path}: {lg.dropped} records dropped after {lg.error}", file=sys.stderr)
        if lg:
            self.finish()
            for topic, rec in self.gcs_budget.summaries(time.time_ns(), force=True):
                lg.log(topic, self._sim_ns(), rec, publish_ns=time.time_ns())
            for name, rec in metadata.items():
                lg.metadata(name, rec)
            lg.close()
            self.logger = None
        if self.fox is not None:
            self.fox.close()
            self.fox = None
