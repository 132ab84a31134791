"""The in-process runner's log on the second core (navig8-sim --log-writer process, the default for a single run).

The closed loop hands each step's records to a forked writer process, which builds the very same log the inline
TickLog builds (the /truth and /analysis/eig records, the FC's status, the Foxglove channels, the MCAP writes): the
files' messages are identical, so are the summaries read from them (tests/integration/test_log_writer.py).

What crosses the process boundary is only what the writer cannot rebuild, in forms cheap to make (StepEncoder):
the FC's status as the JSON its /fc/status record is (the bulk of a step's log, serialised once, by the function the
inline log uses), the plant's truth as the bytes of its state vectors (Plant.truth_state), the eigenvalues' inputs,
the estimated pose the 3D view draws, the command, the setpoint only when the flight stack hands a new one, pickled
(reading the eigenvalues' inputs back from the status's JSON instead saved the loop nothing measurable and cost the
writer a parse). Batches of ~256 KB (a marshalled list of the steps' bytes) go down a pipe with a 1 MB buffer; the
writer rebuilds the records and logs them (docs/results.md, "Speed": what each side costs a step). Campaign workers
log inline (their pool already uses both cores; a daemonic worker may not fork), and so does any run where `fork` is
unavailable.
"""

from __future__ import annotations

import marshal
import multiprocessing as mp
import pickle
from collections.abc import Callable
from typing import Any, NamedTuple, Protocol

from navig8_fc.core.controller import ActuatorCommand, FcSensors
from navig8_fc.core.outer_loop import Setpoint
from navig8_fc.flight import StepResult
from navig8_fc.mavlink.seam import TruthFloats
from navig8_fc.shell.mcap_log import dumps_json
from sim_bridge.plant import Plant, truth_floats_of_state

BATCH_BYTES = 256 * 1024  # one pipe write per ~80 steps: the write's cost spread, the writer never starved
PIPE_BYTES = 1024 * 1024  # the pipe's buffer (Linux's default 64 KB, and its most for a user: 1 MB): a batch goes
# in one write, the loop waiting only when the writer is four batches behind
OPEN_TIMEOUT_S = 60.0  # the writer opens the log (and the viewer's meshes) before the loop starts
JOIN_TIMEOUT_S = 120.0  # the writer drains its backlog (at most one batch and the pipe's buffer) well inside this


class LogWriterError(RuntimeError):
    """The log could not be opened, or its writer failed (the log is then incomplete)."""


class StepRecorder(Protocol):
    """What the writer process feeds: tools.sim.TickLog (record, then finish) and the logger it writes to."""

    def record(self, t_ns: int, truth: TruthFloats, sensors: Any, status: Any, command: ActuatorCommand,
               setpoint: Setpoint, statustexts: list[tuple[int, str]], status_json: bytes | None = None) -> None: ...

    def close(self) -> None: ...


class StatusForLog(NamedTuple):
    """What the per-step log reads from the FC's status besides its JSON: the eigenvalues' inputs and the 3D view's
    estimated joints (shell.step_log.StepLog with status_json)."""

    q_est_rad: Any
    gi_hat: Any
    gc_uam: Any
    ref_frd_m: Any


class SensorsForLog(NamedTuple):
    """What the per-step log reads from the FC's sensors: the 3D view's estimated pose (shell.step_log.StepLog)."""

    pos_ned_m: Any
    quat_wxyz: Any
    duct_tilt_rad: Any


def _frozen(cls: type, fields: dict[str, Any]) -> Any:
    # a frozen dataclass with exactly these fields, in this order (as its __init__ made them), without re-running
    # __init__'s checks: the record was valid when the loop made it
    obj = object.__new__(cls)
    obj.__dict__.update(fields)
    return obj


Item = tuple[bytes, bytes]  # one step: its records (pickled), the status's JSON


class StepEncoder:
    """The loop's side: one step as an Item. What crosses is what the writer cannot rebuild: the status as the JSON
    its /fc/status record is (serialised once, by the function the inline log uses: ~3 kB, the bulk of the step),
    the truth as the bytes of the plant's state vectors, the eigenvalues' inputs, the estimated pose the 3D view
    draws, the command, the setpoint when it is a new one (the flight stack hands the same object back while it
    holds), the STATUSTEXTs."""

    def __init__(self) -> None:
        self._setpoint: Any = None

    def encode(self, t_ns: int, truth_state: Any, res: StepResult, sensors: FcSensors) -> Item:
        st, sp = res.status, res.setpoint
        new_sp = None if sp is self._setpoint else sp.__dict__
        self._setpoint = sp
        texts = [(n.severity, n.statustext) for n in res.notices if n.statustext]
        rec = (t_ns, truth_state, (sensors.pos_ned_m, sensors.quat_wxyz, sensors.duct_tilt_rad),
               (st.q_est_rad, st.gi_hat, st.gc_uam, st.ref_frd_m), res.command.__dict__, new_sp, texts)
        # pickle, not marshal: as fast here, and marshal writes any buffer, a numpy scalar among them, as bytes
        return pickle.dumps(rec, protocol=pickle.HIGHEST_PROTOCOL), dumps_json(st)


class StepDecoder:
    """The writer's side: an Item back as StepRecorder.record's arguments."""

    def __init__(self) -> None:
        self._setpoint: Setpoint | None = None

    def decode(self, item: Item) -> tuple[Any, ...]:
        head, status_json = item
        t_ns, truth_state, pose, eig_in, cd, spd, texts = pickle.loads(head)
        if spd is not None:
            self._setpoint = _frozen(Setpoint, spd)
        return (t_ns, truth_floats_of_state(truth_state), SensorsForLog(*pose), StatusForLog(*eig_in),
                _frozen(ActuatorCommand, cd), self._setpoint, texts, status_json)


def _serve(make_recorder: Callable[[], StepRecorder], conn: Any, other_end: Any, status: Any) -> None:
    other_end.close()  # the loop's end, inherited through fork: closed, so the loop's close ends recv_bytes here
    try:
        recorder = make_recorder()
    except Exception as exc:  # the log cannot open: the loop hears why before it flies (and says it; no traceback)
        status.send(f"{type(exc).__name__}: {exc}")
        raise SystemExit(1) from exc
    status.send(None)
    decoder = StepDecoder()
    try:
        while True:
            try:
                batch = conn.recv_bytes()
            except EOFError:
                break
            for item in marshal.loads(batch):
                recorder.record(*decoder.decode(item))
    except Exception as exc:
        status.send(f"{type(exc).__name__}: {exc}")
        raise
    finally:
        recorder.close()


def _grow_pipe(fd: int) -> None:
    try:
        import fcntl

        fcntl.fcntl(fd, fcntl.F_SETPIPE_SZ, PIPE_BYTES)
    except (ImportError, AttributeError, OSError):  # not Linux, or over the system's limit: the default buffer
        pass


class ProcessTickLog:
    """The step hook of tools.sim.fly that logs on a forked writer process. `make_recorder` runs in the writer
    (after the fork) and returns the recorder every step is replayed into; `finish` waits for it to close the log
    and raises if the writer failed (the log is then incomplete)."""

    def __init__(self, plant: Plant, make_recorder: Callable[[], StepRecorder]) -> None:
        ctx = mp.get_context("fork")
        recv, self._send = ctx.Pipe(duplex=False)
        _grow_pipe(self._send.fileno())
        self._status, status_end = ctx.Pipe(duplex=False)
        self._proc = ctx.Process(target=_serve, args=(make_recorder, recv, self._send, status_end),
                                 name="navig8-log-writer", daemon=True)
        self._proc.start()
        recv.close()
        status_end.close()
        self._plant = plant
        self._encoder = StepEncoder()
        self._parts: list[Item] = []
        self._n_bytes = 0
        self._broken: str | None = None
        opened = self._status.poll(OPEN_TIMEOUT_S)
        error = self._status.recv() if opened else f"the log writer did not start within {OPEN_TIMEOUT_S:.0f} s"
        if error is not None:
            self._send.close()
            self._proc.join(5.0)
            if self._proc.is_alive():
                self._proc.terminate()
            raise LogWriterError(f"the log cannot be written: {error}")

    def tick(self, t_ns: int, s: FcSensors, res: StepResult) -> None:
        item = self._encoder.encode(t_ns, self._plant.truth_state(), res, s)
        self._parts.append(item)
        self._n_bytes += len(item[0]) + len(item[1])
        if self._n_bytes >= BATCH_BYTES:
            self._flush()

    def _flush(self) -> None:
        if self._parts and self._broken is None:
            try:
                self._send.send_bytes(marshal.dumps(self._parts))
            except OSError as exc:  # the writer died: keep flying, report at finish
                self._broken = str(exc)
        self._parts.clear()
        self._n_bytes = 0

    def finish(self) -> None:
        self._flush()
        self._send.close()
        self._proc.join(JOIN_TIMEOUT_S)
        if self._proc.is_alive():
            self._proc.terminate()
            self._proc.join(5.0)
            raise LogWriterError(f"the log writer did not finish within {JOIN_TIMEOUT_S:.0f} s; the log is incomplete")
        if self._proc.exitcode != 0 or self._broken is not None:
            reason = self._status.recv() if self._status.poll(0) else self._broken
            raise LogWriterError(f"the log writer failed (exit code {self._proc.exitcode}: {reason}); "
                               "the log is incomplete")


def process_writer_available() -> bool:
    """A forked writer is possible: `fork` exists and this process may have children (a daemonic pool worker may
    not)."""
    return "fork" in mp.get_all_start_methods() and not mp.current_process().daemon


__all__ = ["LogWriterError", "ProcessTickLog", "StepRecorder", "process_writer_available", "BATCH_BYTES"]
