"""The flight controller's part of a scenario (params/scenarios/*.yaml): the setpoint script.

A scenario file describes a world (initial state, object events, the arm's schedule: `sim_bridge.scenario`) and
what the flight controller flies in it: the keys `name`, `duration_s`, `armed` (the vehicle starts armed in the
air, running the script as AUTO.MISSION) and `setpoints` (Eq. 25 in NED: an initial setpoint and steps). This
module is the one parser of those keys and the one reader of the YAML files; `sim_bridge.scenario` builds on it
(the allowed direction: the FC never imports the bridge).

Units: positions NED (m); the file's `*_deg` channels become radians here. A setpoint key left out of
`setpoints.initial` defaults to the scenario's initial pose (`initial.pos_ned_m`, the yaw of `initial.euler_deg`),
so a file that does not script anything holds where the vehicle starts.
"""

from __future__ import annotations

import math
from bisect import bisect_right
from dataclasses import dataclass
from functools import cached_property
from importlib.resources import files
from pathlib import Path
from typing import Any

from navig8_fc.core.outer_loop import Setpoint
from navig8_fc.modes.manager import MissionScript
from navig8_fc.yaml_text import safe_load

Vec3 = tuple[float, float, float]

SETPOINT_CHANNELS = ("x_ned_m", "y_ned_m", "z_ned_m", "pitch_deg", "yaw_deg")


@dataclass(frozen=True)
class ArmSegment:
    """Joint target moving linearly from q_start at t0 to q_end at t1 (t1 == t0: a step to q_end)."""

    t0_s: float
    t1_s: float
    q_start_rad: Vec3
    q_end_rad: Vec3


@dataclass(frozen=True)
class FlightScript:
    """What the flight controller flies in a scenario: the setpoint at each time, armed in the air or not."""

    name: str
    duration_s: float
    starts_armed_in_air: bool
    setpoint0: Setpoint
    steps: tuple[tuple[float, str, float], ...]  # (t_s, channel, value in SI units), sorted by time
    # the arm's commanded joint targets (the scenario's `arm` key, sim time): the bridge's servo follows them, and
    # the FC's arm preview (INDI_ARM_FF = 2) predicts the arm's reaction from them
    arm_plan: tuple[ArmSegment, ...] = ()

    @property
    def scripted(self) -> bool:
        """A script to fly (steps, or an air start holding its initial setpoint) rather than a GCS-driven run."""
        return bool(self.steps) or self.starts_armed_in_air

    def setpoint_at(self, t_s: float) -> Setpoint:
        """The setpoint in force at script time t_s (each step holds from its time on: u(t - t_k), Eq. 25)."""
        times, setpoints = self._segments
        return setpoints[bisect_right(times, t_s)]

    @cached_property
    def _segments(self) -> tuple[tuple[float, ...], tuple[Setpoint, ...]]:
        """The step times and the setpoint in force from each on (the first before any step): worked out once, so
        the mission's step looks its setpoint up instead of replaying the steps every control tick."""
        sp0 = self.setpoint0
        x, y, z = sp0.pos_ned_m
        pitch, yaw = sp0.pitch_rad, sp0.yaw_rad
        times: list[float] = []
        setpoints = [Setpoint((x, y, z), pitch, yaw)]
        for t, ch, v in self.steps:
            if ch == "x_ned_m":
                x = v
            elif ch == "y_ned_m":
                y = v
            elif ch == "z_ned_m":
                z = v
            elif ch == "pitch_deg":
                pitch = v
            else:
                yaw = v
            sp = Setpoint((x, y, z), pitch, yaw)
            if times and times[-1] == t:  # several channels at one time: one segment
                setpoints[-1] = sp
            else:
                times.append(t)
                setpoints.append(sp)
        return tuple(times), tuple(setpoints)

    def mission(self) -> MissionScript | None:
        """The script as the mode manager's AUTO.MISSION, or None when there is nothing to fly."""
        if not self.scripted:
            return None
        return MissionScript(self.name, self.setpoint_at, starts_armed_in_air=self.starts_armed_in_air,
                             duration_s=self.duration_s, yields_to_plan=not self.steps)


def vec3(v: Any, deg: bool = False) -> Vec3:
    """Three numbers from a YAML list (degrees to radians with deg=True)."""
    if len(v) != 3:
        raise ValueError(f"expected 3 values, got {v!r}")
    f = math.radians if deg else float
    return (f(float(v[0])), f(float(v[1])), f(float(v[2])))


def parse_flight_script(d: dict[str, Any]) -> FlightScript:
    """The FC's keys of a scenario dict (module docstring)."""
    ini = d.get("initial", {})
    sp = d.get("setpoints", {})
    sp0 = sp.get("initial", {})
    initial_yaw_deg = math.degrees(vec3(ini.get("euler_deg", [0.0, 0.0, 0.0]), deg=True)[2])
    setpoint0 = Setpoint(
        pos_ned_m=vec3(sp0.get("pos_ned_m", ini.get("pos_ned_m", [0.0, 0.0, 0.0]))),
        pitch_rad=math.radians(float(sp0.get("pitch_deg", 0.0))),
        yaw_rad=math.radians(float(sp0.get("yaw_deg", initial_yaw_deg))),
    )
    steps: list[tuple[float, str, float]] = []
    for st in sp.get("steps", []):
        t = float(st["t_s"])
        for ch in SETPOINT_CHANNELS:
            if ch in st:
                v = float(st[ch])
                # internal units: radians; the channel keeps its YAML name for traceability
                steps.append((t, ch, math.radians(v) if ch.endswith("_deg") else v))
        unknown = set(st) - set(SETPOINT_CHANNELS) - {"t_s", "note"}
        if unknown:
            raise ValueError(f"unknown setpoint channels {sorted(unknown)}")
    steps.sort(key=lambda s: s[0])
    arm = d.get("arm", {"kind": "hold"})
    q0 = vec3(ini.get("joint_pos_deg", [0.0, 0.0, 0.0]), deg=True)
    return FlightScript(
        name=str(d["name"]),
        duration_s=float(d["duration_s"]),
        starts_armed_in_air=bool(d.get("armed", True)),
        setpoint0=setpoint0,
        steps=tuple(steps),
        arm_plan=arm_segments(str(arm["kind"]), arm, q0, float(d["duration_s"])),
    )


def target_at(seg: ArmSegment, t_s: float) -> Vec3:
    """The joint target of one segment at t_s >= seg.t0_s (the same linear interpolation as the plant's kernel)."""
    if t_s >= seg.t1_s:
        return seg.q_end_rad
    f = (t_s - seg.t0_s) / (seg.t1_s - seg.t0_s)
    a, b = seg.q_start_rad, seg.q_end_rad
    return (a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1]), a[2] + f * (b[2] - a[2]))


def arm_segments(kind: str, arm: dict[str, Any], q0: Vec3, duration_s: float) -> tuple[ArmSegment, ...]:
    """The arm's commanded joint targets from a scenario's `arm` key (kinds hold, steps, eq26).

    steps: `steps: [{t_s, q_deg, ramp_s}]`, sorted by t_s. Without `ramp_s` (or 0) the target jumps to q_deg at
    t_s; with it the target moves linearly from wherever it is at t_s (a ramp still under way is cut there, so
    the target never jumps) to q_deg over ramp_s seconds: a slow sweep is one long ramp."""
    if kind == "hold":
        q = vec3(arm["q_deg"], deg=True) if "q_deg" in arm else q0
        return (ArmSegment(0.0, 0.0, q, q),)
    if kind == "steps":
        segs = [ArmSegment(0.0, 0.0, q0, q0)]
        for st in arm["steps"]:
            q = vec3(st["q_deg"], deg=True)
            t = float(st["t_s"])
            ramp = float(st.get("ramp_s", 0.0))
            if not (math.isfinite(t) and math.isfinite(ramp) and ramp >= 0.0):
                raise ValueError(f"arm step {st!r}: t_s must be finite and ramp_s >= 0")
            if t < segs[-1].t0_s:
                raise ValueError(f"arm steps must be sorted by t_s ({t} after {segs[-1].t0_s})")
            unknown = set(st) - {"t_s", "q_deg", "ramp_s", "note"}
            if unknown:
                raise ValueError(f"arm step: unknown keys {sorted(unknown)} (t_s, q_deg, ramp_s, note)")
            # a step's start value is never read (the target is q_end from t0 on); it stays the previous end, as
            # it always was, so the schedules of step-only files are the same bits
            start = target_at(segs[-1], t) if ramp > 0.0 else segs[-1].q_end_rad
            segs.append(ArmSegment(t, t + ramp, start, q))
        return tuple(segs)
    if kind == "eq26":
        # Eq. 26 as read in notes §6.2: q_cmd = A [1 + sum_k (-1)^k 2 u(t - T k)] = A (-1)^floor(t/T),
        # a +-A square wave starting at +A (Pose 1). The paper's "gradually" from q = 0 to Pose 1 is a
        # linear ramp of the command over [0, ramp_s] (ramp_s <= T), then Eq. 26 from there on.
        a = math.radians(float(arm["amplitude_deg"]))
        period = float(arm["half_period_s"])
        ramp = float(arm.get("ramp_s", 0.0))
        if not 0.0 <= ramp <= period:
            raise ValueError("eq26 ramp_s must lie in [0, half_period_s]")
        pose1 = (a, a, a)
        segs = [ArmSegment(0.0, ramp, q0, pose1)]
        k = 1
        while k * period <= duration_s + 1e-9:
            v = a if k % 2 == 0 else -a
            segs.append(ArmSegment(k * period, k * period, segs[-1].q_end_rad, (v, v, v)))
            k += 1
        return tuple(segs)  # after duration_s the last target holds
    raise ValueError(f"unknown arm command kind {kind!r} (hold, steps, eq26)")


def read_scenario_file(name_or_path: str | Path) -> dict[str, Any]:
    """A scenario's YAML as a dict: by name (params/scenarios/<name>.yaml, package navig8_params.scenarios) or
    by path (a .yaml/.yml suffix or a directory part)."""
    p = Path(name_or_path)
    if isinstance(name_or_path, Path) or p.suffix in (".yaml", ".yml") or len(p.parts) > 1:
        text = p.read_text()
    else:
        res = files("navig8_params.scenarios") / f"{name_or_path}.yaml"
        if not res.is_file():
            raise FileNotFoundError(f"no scenario named {name_or_path!r} in params/scenarios/")
        text = res.read_text()
    return safe_load(text)


def load_flight_script(name_or_path: str | Path) -> FlightScript:
    """The setpoint script of a scenario file (by name or path, as `read_scenario_file`)."""
    return parse_flight_script(read_scenario_file(name_or_path))
