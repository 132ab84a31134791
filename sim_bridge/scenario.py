"""Scenarios (params/scenarios/*.yaml): the world's part (initial state, object events, arm commands).

A scenario is data: the plant reads the initial state, the object events and the arm command
schedule; the flight controller reads its setpoint script (`name`, `duration_s`, `armed`, `setpoints`)
through `navig8_fc.flight.script`, which also reads the files; `Scenario.script` is that same parse, so
each key has one parser. Everything is stored in NED/FRD; the
paper's ENU commands (Eq. 25) are kept beside them as printed, and the mapping is E -> y_NED,
N -> x_NED, U -> -z_NED, yaw_NED = 90 deg - yaw_ENU (ENU yaw is measured from east, counter-clockwise;
NED yaw from north, clockwise), pitch nose-up positive in both (docs/plant.md).

    scn = load_scenario("paper")          # or a path to a YAML file
    scn.arm_targets(3.0)                  # joint targets (rad) at t = 3 s
    scn.object_mass(7.0)                  # kg
    scn.script.setpoint_at(12.0)          # the FC's setpoint (navig8_fc.flight.script.FlightScript)
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from navig8_fc.flight.script import ArmSegment, FlightScript, parse_flight_script, read_scenario_file, vec3

Vec3 = tuple[float, float, float]

EVENT_KINDS = ("grasp", "release", "mass")


@dataclass(frozen=True)
class ObjectEvent:
    """grasp: the gripper closes on an object of mass_kg; release: it opens (mass 0);
    mass: the held object's mass becomes mass_kg (the paper's 1 -> 2 kg at t = 6 s)."""

    t_s: float
    kind: str
    mass_kg: float

    def __post_init__(self) -> None:
        if self.kind not in EVENT_KINDS:
            raise ValueError(f"unknown object event kind {self.kind!r} (expected one of {EVENT_KINDS})")
        if not (math.isfinite(self.t_s) and self.t_s >= 0.0 and self.mass_kg >= 0.0):
            raise ValueError(f"invalid object event {self}")


@dataclass(frozen=True)
class InitialState:
    pos_ned_m: Vec3
    vel_ned_m_s: Vec3
    euler_rad: Vec3  # roll, pitch, yaw (ZYX, NED)
    rate_frd_rad_s: Vec3
    joint_pos_rad: Vec3
    actuators: str  # "trim": at hover trim for the initial pose and object; "off": all zero
    on_ground: bool  # place the skids on the ground (z from the contact geometry)


@dataclass(frozen=True)
class Scenario:
    script: FlightScript  # name, duration, armed start and the FC's setpoints
    description: str
    initial: InitialState
    object_mass_kg: float  # held at t = 0
    gripper_closed: bool  # at t = 0
    events: tuple[ObjectEvent, ...]
    arm_kind: str
    arm_segments: tuple[ArmSegment, ...]
    paper_text: str

    @property
    def name(self) -> str:
        return self.script.name

    @property
    def duration_s(self) -> float:
        return self.script.duration_s

    @property
    def armed(self) -> bool:
        """Starts armed in the air (the plant at trim, the FC flying its script)."""
        return self.script.starts_armed_in_air

    # ---- arm ------------------------------------------------------------------------------------
    def arm_targets(self, t_s: float) -> np.ndarray:
        """Commanded joint angles (rad) at t_s; the plant's servo follows them (same lookup as the kernel)."""
        segs = self.arm_segments
        if t_s < segs[0].t0_s:
            return np.array(segs[0].q_start_rad)
        i = bisect.bisect_right([s.t0_s for s in segs], t_s) - 1
        s = segs[i]
        if t_s >= s.t1_s:
            return np.array(s.q_end_rad)
        f = (t_s - s.t0_s) / (s.t1_s - s.t0_s)
        return np.array(s.q_start_rad) + f * (np.array(s.q_end_rad) - np.array(s.q_start_rad))

    def arm_schedule(self) -> np.ndarray:
        """Rows [t0_us, t1_us, qa(3), qb(3)] for the plant's kernel."""
        rows = [
            [round(s.t0_s * 1e6), round(s.t1_s * 1e6), *s.q_start_rad, *s.q_end_rad]
            for s in self.arm_segments
        ]
        return np.array(rows, dtype=np.float64)

    # ---- object ---------------------------------------------------------------------------------
    def object_mass(self, t_s: float) -> float:
        """Mass of the held object (kg) at t_s, 0 when the gripper is open."""
        m = self.object_mass_kg if self.gripper_closed else 0.0
        for ev in self.events:
            if ev.t_s <= t_s:
                m = 0.0 if ev.kind == "release" else ev.mass_kg
        return m

    def gripper_closed_at(self, t_s: float) -> bool:
        closed = self.gripper_closed
        for ev in self.events:
            if ev.t_s <= t_s:
                closed = ev.kind != "release"
        return closed

    # ---- construction -----------------------------------------------------------------------
    @staticmethod
    def from_dict(d: dict[str, Any]) -> Scenario:
        script = parse_flight_script(d)
        ini = d["initial"]
        q0 = vec3(ini.get("joint_pos_deg", [0.0, 0.0, 0.0]), deg=True)
        actuators = str(ini.get("actuators", "trim"))
        if actuators not in ("trim", "off"):
            raise ValueError(f"initial.actuators must be 'trim' or 'off', got {actuators!r}")
        initial = InitialState(
            pos_ned_m=vec3(ini.get("pos_ned_m", [0.0, 0.0, 0.0])),
            vel_ned_m_s=vec3(ini.get("vel_ned_m_s", [0.0, 0.0, 0.0])),
            euler_rad=vec3(ini.get("euler_deg", [0.0, 0.0, 0.0]), deg=True),
            rate_frd_rad_s=vec3(ini.get("rate_frd_rad_s", [0.0, 0.0, 0.0])),
            joint_pos_rad=q0,
            actuators=actuators,
            on_ground=bool(ini.get("on_ground", False)),
        )
        obj = d.get("object", {})
        events = tuple(
            ObjectEvent(float(e["t_s"]), str(e["kind"]), float(e.get("mass_kg", 0.0)))
            for e in d.get("events", [])
        )
        if list(events) != sorted(events, key=lambda e: e.t_s):
            raise ValueError("scenario events must be sorted by time")
        kind = str(d.get("arm", {"kind": "hold"})["kind"])
        segments = script.arm_plan  # parsed with the FC's script (the FC's arm preview reads the same plan)
        return Scenario(
            script=script,
            description=str(d.get("description", "")),
            initial=initial,
            object_mass_kg=float(obj.get("mass_kg", 0.0)),
            gripper_closed=bool(obj.get("gripper_closed", False)),
            events=events,
            arm_kind=kind,
            arm_segments=segments,
            paper_text=str(d.get("paper_text", "")),
        )


def load_scenario(name_or_path: str | Path) -> Scenario:
    """Load a scenario by name (params/scenarios/<name>.yaml, package navig8_params.scenarios) or path."""
    return Scenario.from_dict(read_scenario_file(name_or_path))
