"""The Foxglove channels (navig8_fc.viz records) to the MCAP log and, with --foxglove, live over Foxglove's
WebSocket protocol (foxglove-sdk's server). One writer for navig8-fc and navig8-sim (docs/foxglove.md).

Rates are on the log time (sim time), so a lockstep run faster than real time writes the same records, and
are display rates (docs/foxglove.md; docs/logs.md, "Rates"): transforms and pose 10 Hz (the 3D panel
interpolates between transforms), the scene 5 Hz (its entities ride on the transforms' frames; only the thrust
arrows, the object and the setpoint ghost change), path and mission 2 Hz, every STATUSTEXT. A record is built
and serialised only when a sink wants it: the log always, a live channel only while a client subscribes to it
(`Channel.has_sinks`), so a server nobody is connected to costs one check per publication time.
"""

from __future__ import annotations

import json
from collections import deque
from collections.abc import Callable, Iterable, Sequence
from typing import Any

import orjson

from navig8_fc import viz
from navig8_fc.mission.executor import planned_path
from navig8_fc.mission.geo import GeoOrigin
from navig8_fc.mission.plan import Plan
from navig8_fc.shell.mcap_log import McapLogger
from navig8_fc.shell.origin_gate import DEFAULT_ALLOWED_ORIGINS, OriginGate

_NS = 1_000_000_000
# topic: (Foxglove schema, period in ns of log time)
TOPICS: dict[str, tuple[str, int]] = {
    "/foxglove/tf": (viz.FRAME_TRANSFORMS, _NS // 10),
    "/foxglove/scene": (viz.SCENE_UPDATE, _NS // 5),
    "/foxglove/pose": (viz.POSE_IN_FRAME, _NS // 10),
    "/foxglove/path": (viz.POSES_IN_FRAME, _NS // 2),
    "/foxglove/mission": (viz.POSES_IN_FRAME, _NS // 2),
    "/foxglove/log": (viz.LOG, 0),
}
PATH_LENGTH = 600  # path poses kept (5 min at 2 Hz): the path record stays a few tens of kB
DEFAULT_PORT = 8765  # Foxglove's default WebSocket port


class FoxglovePortError(OSError):
    """The Foxglove WebSocket server could not start on the port asked for."""

    def __init__(self, port: int, reason: str) -> None:
        super().__init__(f"Foxglove WebSocket port {port}: {reason}")
        self.port = port


class LiveServer:
    """A foxglove-sdk WebSocket server with one JSON channel per TOPICS entry (its own Context: no globals), behind an
    OriginGate on (host, port): the SDK's server listens on a loopback port of its own, and a browser page from an
    origin not in `allowed_origins` is refused (origin_gate.py)."""

    def __init__(self, host: str, port: int, name: str,
                 allowed_origins: Iterable[str] = DEFAULT_ALLOWED_ORIGINS) -> None:
        import foxglove  # imported only with --foxglove

        self._ctx = foxglove.Context()
        self.channels: dict[str, Any] = {}
        for topic, (schema, _period) in TOPICS.items():
            data = json.dumps(dict(viz.channel_schema(schema), title=schema)).encode()
            self.channels[topic] = foxglove.Channel(
                topic, schema=foxglove.Schema(name=schema, encoding="jsonschema", data=data),
                message_encoding="json", context=self._ctx)
        try:
            self.server = foxglove.start_server(name=name, host="127.0.0.1", port=0, context=self._ctx)
        except RuntimeError as e:  # foxglove-sdk's FoxgloveError, e.g. "Failed to bind port: Address already in use"
            raise FoxglovePortError(port, str(e)) from e
        try:
            self.gate = OriginGate(host, port, int(self.server.port), allowed_origins)
        except OSError as e:
            self.server.stop()
            raise FoxglovePortError(port, e.strerror or str(e)) from e

    @property
    def port(self) -> int:
        """Where clients connect (the gate)."""
        return self.gate.port

    def wants(self, topic: str) -> bool:
        return bool(self.channels[topic].has_sinks())

    def log(self, topic: str, t_ns: int, data: bytes) -> None:
        self.channels[topic].log(data, log_time=t_ns)

    def close(self) -> None:
        self.gate.close()
        self.server.stop()


class FoxgloveOutput:
    """Rate-limited Foxglove records of one vehicle to an MCAP logger and/or a live server."""

    def __init__(self, vehicle_viz: viz.VehicleViz, logger: McapLogger | None, live: LiveServer | None,
                 name: str) -> None:
        self.viz = vehicle_viz
        self.logger = logger
        self.live = live
        self.name = name
        self._cid: dict[str, int] = {}
        if logger is not None:
            for topic, (schema, _period) in TOPICS.items():
                self._cid[topic] = logger.channel(topic, None, schema_name=schema, schema=viz.channel_schema(schema))
        self._due = dict.fromkeys(TOPICS, -1)
        self.next_due_ns = -1  # the earliest time any periodic channel is due (one compare per step)
        self._path: deque[dict[str, Any]] = deque(maxlen=PATH_LENGTH)  # world poses, built once each
        self._mission: list[tuple[Sequence[float], Sequence[float]]] | None = None

    def set_mission(self, poses: list[tuple[Sequence[float], Sequence[float]]] | None) -> None:
        """The mission's waypoints as (pos NED, q_NED<-FRD) poses (viz.waypoint_poses), or None: published on
        /foxglove/mission while set. The hook for a mission store: call it when the mission changes."""
        self._mission = poses

    def _emit(self, topic: str, t_ns: int, build: Callable[[], dict[str, Any]], wall_ns: int | None) -> None:
        live = self.live is not None and self.live.wants(topic)
        if self.logger is None and not live:
            return
        data = orjson.dumps(build())
        if self.logger is not None:
            self.logger.log_json_bytes(self._cid[topic], t_ns, data, t_ns if wall_ns is None else wall_ns)
        if live:
            assert self.live is not None
            self.live.log(topic, t_ns, data)

    def _take(self, topic: str, t_ns: int) -> bool:
        due = self._due[topic]
        if t_ns < due:
            return False
        period = TOPICS[topic][1]
        # the next slot on the period's grid (never two records for one slot, whatever the step)
        self._due[topic] = (t_ns // period + 1) * period
        return True

    def step(self, t_ns: int, truth: viz.VehiclePose, speed_rad_s: Sequence[float], object_mass_kg: float,
             estimate: viz.VehiclePose | None, setpoint: Any, wall_ns: int | None = None) -> None:
        """The periodic channels due at log time t_ns. truth: the plant's pose and joints; estimate: the FC's
        view (its sensors' pose and tilts, q_est), drawn on the est/ tree; setpoint: outer_loop.Setpoint."""
        if t_ns < self.next_due_ns:
            return
        v = self.viz
        if self._take("/foxglove/tf", t_ns):
            trees = [("", truth)] if estimate is None else [("", truth), (viz.ESTIMATE_PREFIX, estimate)]
            self._emit("/foxglove/tf", t_ns, lambda: v.frame_transforms(t_ns, trees), wall_ns)
        if self._take("/foxglove/scene", t_ns):
            sp = setpoint
            self._emit("/foxglove/scene", t_ns, lambda: v.scene_update(
                t_ns, speed_rad_s, object_mass_kg, None if sp is None else sp.pos_ned_m,
                0.0 if sp is None else sp.pitch_rad, 0.0 if sp is None else sp.yaw_rad), wall_ns)
        if self._take("/foxglove/pose", t_ns):
            self._emit("/foxglove/pose", t_ns, lambda: v.pose_in_frame(t_ns, truth.pos_ned_m, truth.quat_wxyz),
                       wall_ns)
        if self._take("/foxglove/path", t_ns):
            self._path.append(viz.world_pose(truth.pos_ned_m, truth.quat_wxyz))
            self._emit("/foxglove/path", t_ns, lambda: viz.poses_record(t_ns, list(self._path)), wall_ns)
        if self._take("/foxglove/mission", t_ns) and self._mission is not None:
            mission = self._mission
            self._emit("/foxglove/mission", t_ns, lambda: v.poses_in_frame(t_ns, mission), wall_ns)
        self.next_due_ns = min(due for topic, due in self._due.items() if TOPICS[topic][1] > 0)

    def statustext(self, t_ns: int, severity: int, text: str, wall_ns: int | None = None) -> None:
        """A STATUSTEXT as foxglove.Log (every one)."""
        self._emit("/foxglove/log", t_ns, lambda: viz.log_record(t_ns, severity, text, self.name), wall_ns)

    def close(self) -> None:
        if self.live is not None:
            self.live.close()
            self.live = None


class MissionView:
    """What /foxglove/mission shows: the uploaded plan's planned path from home, or the script's waypoints when no
    plan is loaded; drawn again only when the plan changed (its generation)."""

    def __init__(self, fox: FoxgloveOutput, script: Any) -> None:
        self._fox = fox
        self._script_waypoints = script_waypoints(script)
        self._generation: int | None = None  # the uploaded plan last drawn
        fox.set_mission(self._script_waypoints)

    def show(self, generation: int, plan: Callable[[], Plan], origin: GeoOrigin,
             home_ned_m: Callable[[], Sequence[float] | None]) -> None:
        """The plan of `generation` (`plan` and `home_ned_m` are asked only when it is new)."""
        if generation == self._generation:
            return
        self._generation = generation
        items = plan()
        if not items.items:
            self._fox.set_mission(self._script_waypoints)
            return
        path = planned_path(items, origin, home_ned_m() or (0.0, 0.0, 0.0))
        self._fox.set_mission(viz.waypoint_poses([(p, 0.0, 0.0) for p in path]))


def script_waypoints(script: Any) -> list[tuple[Sequence[float], Sequence[float]]] | None:
    """A scripted flight's waypoints (the setpoint in force after each scripted step, from the start's), as
    poses for FoxgloveOutput.set_mission; None when the script flies nothing."""
    if not getattr(script, "scripted", False):
        return None
    times = sorted({0.0, *(t for t, _ch, _v in script.steps)})
    pts = []
    for t in times:
        sp = script.setpoint_at(t)
        if not pts or pts[-1] != (sp.pos_ned_m, sp.pitch_rad, sp.yaw_rad):
            pts.append((sp.pos_ned_m, sp.pitch_rad, sp.yaw_rad))
    return viz.waypoint_poses(pts)


__all__ = ["DEFAULT_PORT", "FoxgloveOutput", "FoxglovePortError", "LiveServer", "MissionView", "TOPICS",
           "script_waypoints"]
