"""Long-running flight commands (takeoff, land, return, reposition): their status and its tracking (pure).

The GCS answers such a command with COMMAND_ACK IN_PROGRESS, progress updates and one final result
(docs/gcs.md "Long-running commands and COMMAND_CANCEL"); `TaskTracker` keeps the one running in the mode
manager: started by the manager's commands, completed by the mode that gets there (Takeoff, Land), cancelled
when another mode is chosen, failed when its mode is left otherwise."""

from __future__ import annotations

import math
from dataclasses import dataclass

from navig8_fc.modes.px4 import FlightMode
from navig8_fc.modes.records import ModeConfig, ModeInputs, Vec3

TASK_RUNNING, TASK_DONE, TASK_FAILED, TASK_CANCELLED = 0, 1, 2, 3  # TaskStatus.state


@dataclass(frozen=True)
class TaskStatus:
    """A long-running command's progress (COMMAND_ACK IN_PROGRESS, then its final result; docs/gcs.md).

    task_id grows with every task started; kind names the command ("takeoff", "land", "return", "reposition",
    "arm_joints"); progress_pct 0..100, never decreasing. A task ends DONE (it got there), CANCELLED (COMMAND_CANCEL,
    or another command took over) or FAILED (a failsafe took over, or it could not complete)."""

    task_id: int
    kind: str
    state: int = TASK_RUNNING
    progress_pct: float = 0.0
    reason: str = ""

    @property
    def running(self) -> bool:
        return self.state == TASK_RUNNING


# The modes a task's own command flies: leaving them otherwise (or disarming) ends the task FAILED.
_OWN_MODES = {"takeoff": (FlightMode.TAKEOFF,), "land": (FlightMode.LAND,), "reposition": (FlightMode.HOLD,),
              "return": (FlightMode.RTL, FlightMode.LAND)}


class TaskTracker:
    """The last long-running flight command (`task`: running, or how it ended) and its start and target."""

    def __init__(self, config: ModeConfig) -> None:
        self._cfg = config
        self.task: TaskStatus | None = None
        self._n = 0
        self._from: Vec3 = (0.0, 0.0, 0.0)
        self._to: Vec3 = (0.0, 0.0, 0.0)

    @property
    def running(self) -> bool:
        return self.task is not None and self.task.running

    def running_kind(self, *kinds: str) -> bool:
        """A task of one of these kinds is running."""
        return self.task is not None and self.task.running and self.task.kind in kinds

    def start(self, kind: str, here: Vec3, to: Vec3) -> None:
        """A new task from `here` to `to`; a running one is CANCELLED, replaced by this one."""
        if self.task is not None and self.task.running:
            self.end(TASK_CANCELLED, f"replaced by {kind}")
        self._n += 1
        self.task = TaskStatus(self._n, kind)
        self._from, self._to = here, to

    def end(self, state: int, reason: str = "") -> None:
        tk = self.task
        assert tk is not None
        self.task = TaskStatus(tk.task_id, tk.kind, state, 100.0 if state == TASK_DONE else tk.progress_pct, reason)

    def complete(self, *kinds: str) -> None:
        """The running task, when of one of these kinds, got there: DONE."""
        if self.task is not None and self.task.running and self.task.kind in kinds:
            self.end(TASK_DONE)

    def mode_changed(self, old: FlightMode, new: FlightMode) -> None:
        """Another mode was chosen: the running task is CANCELLED (Return goes on into its own landing)."""
        tk = self.task
        if tk is not None and tk.running and new is not old and not (tk.kind == "return" and new is FlightMode.LAND):
            self.end(TASK_CANCELLED, f"mode changed to {new.label}")

    def update(self, inp: ModeInputs, mode: FlightMode, armed: bool) -> None:
        """Progress (the share of the start-to-target distance covered, never decreasing) and the end of the running
        task when its mode was left (a command's own ending is set where it happens: touchdown, takeoff done)."""
        tk = self.task
        if tk is None or not tk.running:
            return
        if mode not in _OWN_MODES[tk.kind] or not armed:
            self.end(TASK_FAILED, f"mode changed to {mode.label}")
            return
        d = math.dist(inp.pos_ned_m, self._to)
        if tk.kind == "reposition" and d < self._cfg.reposition_reached_tol_m and math.hypot(
                *inp.vel_ned_m_s) < self._cfg.reposition_reached_speed_m_s:
            self.end(TASK_DONE)
            return
        d0 = math.dist(self._from, self._to)
        pct = 100.0 * min(1.0, max(0.0, 1.0 - d / d0)) if d0 > 1e-6 else 0.0
        if pct > tk.progress_pct:
            self.task = TaskStatus(tk.task_id, tk.kind, TASK_RUNNING, pct)
