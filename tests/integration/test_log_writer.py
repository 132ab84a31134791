"""navig8-sim's log on a second process (tools/log_writer.py) writes the same file as the inline log: every message
(topic, log and publish time, bytes) and every channel's schema equal, so the summary read from it is equal too; a
log that cannot be written is refused before the flight, as the inline log refuses it; a writer that fails mid-run
is reported after the flight."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from navig8_fc.flight import FlightStack
from navig8_fc.params.registry import ParamRegistry
from navig8_tools.log_writer import LogWriterError, ProcessTickLog
from navig8_tools.sim import fly, run
from sim_bridge.plant import Plant
from sim_bridge.world import load_world

DURATION_S = 3.0  # the arm's first move, a position step and a STATUSTEXT (the take-off) inside it


def _messages(path: Path) -> list[tuple[str, int, int, bytes]]:
    with path.open("rb") as f:
        return [(ch.topic, m.log_time, m.publish_time, m.data) for _s, ch, m in make_reader(f).iter_messages()]


def _schemas(path: Path) -> dict[str, tuple[str, bytes]]:
    with path.open("rb") as f:
        return {ch.topic: (s.name, s.data) for s, ch, _m in make_reader(f).iter_messages()}


def _without_wall(summary: dict) -> dict:
    return {k: v for k, v in summary.items() if "wall" not in k and k != "real_time_factor"}


def test_the_process_writer_writes_the_inline_log(tmp_path: Path) -> None:
    inline = run("paper", "proposed", 1, DURATION_S, tmp_path / "inline.mcap", log_writer="inline")
    process = run("paper", "proposed", 1, DURATION_S, tmp_path / "process.mcap", log_writer="process")
    a, b = _messages(tmp_path / "inline.mcap"), _messages(tmp_path / "process.mcap")
    topics = {m[0] for m in a}
    assert {"/truth", "/analysis/eig", "/fc/status", "/fc/command", "/fc/setpoint", "/fc/statustext", "/foxglove/tf",
            "/foxglove/log"} <= topics
    assert len(a) > 4 * int(DURATION_S * 100)  # /truth, /analysis/eig, /fc/status, /fc/command every step
    assert len(a) == len(b)
    first_diff = next((i for i, (x, y) in enumerate(zip(a, b, strict=True)) if x != y), None)
    assert first_diff is None, f"message {first_diff} differs: {a[first_diff][:3]} against {b[first_diff][:3]}"
    assert _schemas(tmp_path / "inline.mcap") == _schemas(tmp_path / "process.mcap")
    assert _without_wall(inline.summary) == _without_wall(process.summary)


def test_a_log_that_cannot_open_is_refused_before_the_flight(tmp_path: Path) -> None:
    blocker = tmp_path / "a_file"
    blocker.write_text("not a directory")
    with pytest.raises(LogWriterError, match="the log cannot be written"):
        run("paper", "proposed", 1, DURATION_S, blocker / "run.mcap", log_writer="process")
    with pytest.raises(OSError):
        run("paper", "proposed", 1, DURATION_S, blocker / "run.mcap", log_writer="inline")


def test_an_unknown_writer_is_refused(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="log_writer"):
        run("paper", "proposed", 1, 0.1, tmp_path / "x.mcap", log_writer="thread")


class _FailsAtStep:
    """A recorder whose disk fails at its 50th step (in the writer process)."""

    def __init__(self) -> None:
        self.n = 0

    def record(self, *_record: object) -> None:
        self.n += 1
        if self.n == 50:
            raise OSError(28, "No space left on device")

    def close(self) -> None:
        pass


def test_a_writer_that_fails_mid_run_is_reported_after_the_flight() -> None:
    w = load_world("paper", None)
    plant = Plant(w.vehicle, w.plant, w.scenario, np.random.default_rng(1))
    stack = FlightStack(w.fc_vehicle, ParamRegistry.from_defaults(), w.scenario.script)
    hook = ProcessTickLog(plant, _FailsAtStep)
    n_steps = 400  # several batches: the sends after the failure find the pipe closed
    fly(plant, stack, n_steps, hook.tick)
    assert plant.truth_floats().time_us >= n_steps * 10_000  # the vehicle flew to the end
    with pytest.raises(LogWriterError, match="No space left on device"):
        hook.finish()


def test_navig8_sim_says_why_a_log_cannot_be_written(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from navig8_tools.sim import main

    blocker = tmp_path / "a_file"
    blocker.write_text("not a directory")
    for writer in ("process", "inline"):
        assert main(["--duration", "0.5", "--log", str(blocker / "run.mcap"), "--log-writer", writer]) == 1
        err = capsys.readouterr().err
        assert err.startswith("navig8-sim: ") and "a_file" in err and "Traceback" not in err, err


class _Keeps:
    """A recorder that writes what it was handed (in the writer process) to a file the test reads back."""

    def __init__(self, path: Path) -> None:
        self.path, self.got = path, []

    def record(self, t_ns, truth, sensors, status, command, setpoint, statustexts, status_json=None) -> None:
        self.got.append((t_ns, type(setpoint.pitch_rad).__name__, float(setpoint.pitch_rad), status_json is not None))

    def close(self) -> None:
        self.path.write_text(repr(self.got))


def _paper_rig(tmp_path: Path, recorder: type) -> tuple[Plant, FlightStack, Path, ProcessTickLog]:
    """The paper scenario's plant and flight stack (seed 1, the defaults) and a forked writer feeding `recorder`,
    which writes what it was handed to the returned path."""
    w = load_world("paper", None)
    plant = Plant(w.vehicle, w.plant, w.scenario, np.random.default_rng(1))
    stack = FlightStack(w.fc_vehicle, ParamRegistry.from_defaults(), w.scenario.script)
    out = tmp_path / "got.txt"
    return plant, stack, out, ProcessTickLog(plant, lambda: recorder(out))


def test_a_numpy_scalar_in_a_record_reaches_the_writer_as_itself(tmp_path: Path) -> None:
    """A numpy scalar in a record reaches the writer as the same numpy scalar (marshal would have made it bytes)."""
    plant, stack, out, hook = _paper_rig(tmp_path, _Keeps)
    seen: list[int] = []

    def with_numpy(t_ns: int, s, res) -> None:
        sp = res.setpoint
        hook.tick(t_ns, s, res._replace(setpoint=type(sp)(sp.pos_ned_m, np.float64(0.25), sp.yaw_rad)))
        seen.append(t_ns)

    fly(plant, stack, 20, with_numpy)
    hook.finish()
    got = eval(out.read_text())  # noqa: S307 - the test's own repr of tuples of numbers and names
    assert [g[0] for g in got] == seen
    assert all(g[1] == "float64" and g[2] == 0.25 and g[3] for g in got)


class _KeepsEigInputs:
    """A recorder that writes the eigenvalues' inputs it was handed (in the writer process) to a file."""

    def __init__(self, path: Path) -> None:
        self.path, self.got = path, []

    def record(self, t_ns, truth, sensors, status, command, setpoint, statustexts, status_json=None) -> None:
        self.got.append(repr((tuple(status.q_est_rad), tuple(status.gi_hat), tuple(status.gc_uam),
                              status.ref_frd_m)))

    def close(self) -> None:
        self.path.write_text("\n".join(self.got))


def test_the_eigenvalues_inputs_reach_the_writer_bit_for_bit_non_finite_ones_too(tmp_path: Path) -> None:
    """q_est, G_hat_I and G_C,UAM reach the writer as the loop's floats exactly, non-finite ones too (the /fc/status
    JSON writes those as null: the eigenvalues are not computed from it)."""
    plant, stack, out, hook = _paper_rig(tmp_path, _KeepsEigInputs)
    sent: list[str] = []

    def some_non_finite(t_ns: int, s, res) -> None:
        st = res.status
        if len(sent) % 3 == 1:
            st = replace(st, gi_hat=(float("nan"), float("inf"), *st.gi_hat[2:]))
        elif len(sent) % 3 == 2:
            st = replace(st, q_est_rad=(float("-inf"), *st.q_est_rad[1:]))
        sent.append(repr((tuple(st.q_est_rad), tuple(st.gi_hat), tuple(st.gc_uam), st.ref_frd_m)))
        hook.tick(t_ns, s, res._replace(status=st))

    fly(plant, stack, 30, some_non_finite)
    hook.finish()
    assert out.read_text().split("\n") == sent
