"""The MAVLink messages that steer the vehicle outside the command protocol (for GcsService; pure, wall times come
in): the legacy SET_MODE, the offboard targets (SET_POSITION_TARGET_*, SET_ATTITUDE_TARGET), MANUAL_CONTROL (sticks
centred when it stops), SET_GPS_GLOBAL_ORIGIN, and the uploaded mission, fence and rally plans handed to the vehicle
about the global origin. None of them has an ACK: a refusal is a STATUSTEXT. Offboard targets and uploaded mission and
rally items are held to the operating volume (navig8_fc.mission.volume, VOL_*): a target outside it is ignored (the
vehicle flies on with the last one it accepted) with a STATUSTEXT at most once a second. DO_ORBIT's centre is placed
about the same origin here (`orbit`, for the command handler's GlobalOrbit)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from navig8_fc.core.rotation import quat_to_euler
from navig8_fc.flight.commands import (
    LoadFence,
    LoadMission,
    LoadRally,
    ManualInput,
    OffboardSetpoint,
    Orbit,
    Reposition,
    SetMode,
    VehicleCommand,
)
from navig8_fc.flight.state import VehicleCommands, VehicleState
from navig8_fc.gcs import offboard
from navig8_fc.gcs.commands import GlobalOrbit
from navig8_fc.gcs.mission_protocol import MissionProtocol
from navig8_fc.gcs.params import ParamProtocol
from navig8_fc.gcs.statustext import StatusTextEncoder
from navig8_fc.mission.geo import origin_from_params
from navig8_fc.mission.plan import MissionItem, MissionType, Problem
from navig8_fc.mission.volume import OperatingVolume
from navig8_fc.modes.manager import Verdict
from navig8_fc.modes.orbit import OrbitRequest
from navig8_fc.params.registry import ParamRegistry

MAV_FRAME_LOCAL_NED, MAV_FRAME_GLOBAL_INT, MAV_FRAME_GLOBAL_RELATIVE_ALT_INT = 1, 5, 6
_OFFBOARD_TYPES = frozenset({"SET_POSITION_TARGET_LOCAL_NED", "SET_POSITION_TARGET_GLOBAL_INT", "SET_ATTITUDE_TARGET"})
MANUAL_CONTROL_TIMEOUT_S = 0.5  # MANUAL_CONTROL older than this: sticks centred (Position mode holds)
VOLUME_TEXT_PERIOD_S = 1.0  # at most one "outside the operating volume" STATUSTEXT a second


class VehicleMessages:
    """The vehicle-steering messages (module docstring). `command` applies a mode change the way the GCS service's
    commands do (remembering the intended mode)."""

    def __init__(self, mav: Any, sysid: int, state: Callable[[], VehicleState], vehicle: VehicleCommands,
                 command: Callable[[VehicleCommand], Verdict], registry: ParamRegistry, params: ParamProtocol,
                 text: StatusTextEncoder) -> None:
        self.mav, self.sysid, self._state, self._vehicle, self._command = mav, sysid, state, vehicle, command
        self._registry, self.params, self.text = registry, params, text
        self.origin = origin_from_params(registry)
        self._plan_generation = -1  # the mission plan generation the vehicle has
        self.last_offboard_setpoint: float | None = None  # wall time of the last accepted offboard setpoint
        self._offboard_ignored = ""  # the part of the offboard targets not flown, as last announced
        self._last_manual: float | None = None  # wall time of the last MANUAL_CONTROL
        self._volume = OperatingVolume.from_params(registry)
        self._volume_generation = registry.generation
        self._volume_text_t = -float("inf")

    def handle(self, m: Any, now_wall: float) -> list[Any]:
        """One inbound message; the answers (STATUSTEXT, PARAM_VALUE, GPS_GLOBAL_ORIGIN) for the caller to route."""
        kind = m.get_type()
        out = self._set_mode(m) + self._offboard(m, now_wall)
        if kind == "SET_GPS_GLOBAL_ORIGIN" and m.target_system in (0, self.sysid):
            out += self._set_origin(m)
        if kind == "MANUAL_CONTROL" and m.target in (0, self.sysid):
            # PX4's scaling: x/y/r -1000..1000, z 0..1000 (500 = hold altitude); missing sticks are centred.
            self._vehicle.command(ManualInput(m.x / 1000.0, m.y / 1000.0, m.z / 1000.0, m.r / 1000.0))
            self._last_manual = now_wall
        return out

    def poll(self, now_wall: float, mission: MissionProtocol) -> None:
        """Sticks centred once MANUAL_CONTROL stops; a new plan, clear or start item (or origin) to the vehicle."""
        if self._last_manual is not None and now_wall - self._last_manual > MANUAL_CONTROL_TIMEOUT_S:
            self._last_manual = None
            self._vehicle.command(ManualInput(0.0, 0.0, 0.5, 0.0))  # sticks no longer received: centred (hold)
        if mission.generation != self._plan_generation:
            self._plan_generation = mission.generation
            self._vehicle.command(LoadMission(mission.plan(), self.origin))
            self._vehicle.command(LoadFence(mission.plan(MissionType.FENCE), self.origin))
            self._vehicle.command(LoadRally(mission.plan(MissionType.RALLY), self.origin))

    def _set_mode(self, m: Any) -> list[Any]:
        """The legacy SET_MODE message (what `mode X` in MAVProxy sends), read in PX4's custom_mode encoding
        as PX4 does; there is no ACK in that protocol, so a refusal is reported by STATUSTEXT."""
        if m.get_type() != "SET_MODE" or m.target_system not in (0, self.sysid):
            return []
        ok, reason = self._command(SetMode(int(m.base_mode), int(m.custom_mode)))
        return [] if ok else self.text.warning(reason or f"SET_MODE {int(m.custom_mode):#x} refused")

    def _offboard(self, m: Any, now_wall: float) -> list[Any]:
        """SET_POSITION_TARGET_LOCAL_NED (frames LOCAL_NED, BODY_NED) / _GLOBAL_INT (GLOBAL_INT,
        GLOBAL_RELATIVE_ALT_INT) and SET_ATTITUDE_TARGET -> the vehicle's offboard target, per type_mask
        (navig8_fc.gcs.offboard). No ACK in this protocol: a refusal is a STATUSTEXT; a part not flown
        (acceleration, roll, ...) is named once until a target without it arrives."""
        kind = m.get_type()
        if kind not in _OFFBOARD_TYPES or m.target_system not in (0, self.sysid) or m.target_component not in (0, 1):
            return []
        if kind == "SET_ATTITUDE_TARGET":
            dec = offboard.attitude_target(int(m.type_mask), tuple(m.q), float(m.thrust),
                                           (m.body_roll_rate, m.body_pitch_rate, m.body_yaw_rate),
                                           tuple(getattr(m, "thrust_body", offboard.NAN3)))
        else:
            mask, frame = int(m.type_mask), int(m.coordinate_frame)
            if kind == "SET_POSITION_TARGET_LOCAL_NED":
                if frame not in (MAV_FRAME_LOCAL_NED, offboard.MAV_FRAME_BODY_NED):
                    return self.text.warning(f"{kind}: frame {frame} unsupported (LOCAL_NED, BODY_NED)")
                pos = (float(m.x), float(m.y), float(m.z))
            else:
                if frame not in (MAV_FRAME_GLOBAL_INT, MAV_FRAME_GLOBAL_RELATIVE_ALT_INT):
                    return self.text.warning(f"{kind}: frame {frame} unsupported (GLOBAL_INT, GLOBAL_RELATIVE_ALT_INT)")
                pos = self.to_ned(m.lat_int * 1e-7, m.lon_int * 1e-7, float(m.alt), frame != MAV_FRAME_GLOBAL_INT)
            sensors = self._state().sensors
            yaw_now = quat_to_euler(sensors.quat_wxyz)[2] if sensors is not None else 0.0
            dec = offboard.position_target(kind, mask, frame, pos, (m.vx, m.vy, m.vz), (m.afx, m.afy, m.afz),
                                           float(m.yaw), float(m.yaw_rate), yaw_now)
        if dec.target is None:
            return self.text.warning(dec.refusal)
        why = self.volume().target_problem(dec.target.pos_ned_m, dec.target.vel_ned_m_s, self._home())
        if why:
            if now_wall - self._volume_text_t < VOLUME_TEXT_PERIOD_S:
                return []
            self._volume_text_t = now_wall
            return self.text.warning(f"Offboard target ignored: {why}")
        ok, reason = self._vehicle.command(OffboardSetpoint(dec.target))
        if not ok:
            return self.text.warning(reason)
        self.last_offboard_setpoint = now_wall
        if dec.ignored == self._offboard_ignored:
            return []
        self._offboard_ignored = dec.ignored
        return self.text.warning(dec.ignored) if dec.ignored else []

    def _set_origin(self, m: Any) -> list[Any]:
        """SET_GPS_GLOBAL_ORIGIN -> the ORIGIN_* parameters (validated and saved as any PARAM_SET), then
        GPS_GLOBAL_ORIGIN and the new PARAM_VALUEs to everyone. Refused while armed (the plan in flight and home
        would jump)."""
        if self._state().armed:
            return self.text.warning("SET_GPS_GLOBAL_ORIGIN denied: vehicle armed")
        reg = self._registry
        names = ("ORIGIN_LAT_E7", "ORIGIN_LON_E7", "ORIGIN_ALT")
        before = {n: reg[n] for n in names}
        results = [reg.set(n, v) for n, v in zip(names, (int(m.latitude), int(m.longitude), m.altitude / 1000.0),
                                                  strict=True)]
        refused = [r for r in results if not r.accepted]
        if refused:  # all or nothing: put back what was set
            for n, v in before.items():
                reg.set(n, v)
            return [self.params.param_value(n) for n in names] + self.text.warning(
                f"SET_GPS_GLOBAL_ORIGIN refused: {refused[0].reason or refused[0].name}")
        out: list[Any] = [self.params.param_value(n) for n in names]
        err = self.params.save()
        if err:
            out += self.text.warning(err)
        self.origin = origin_from_params(reg)
        self._plan_generation = -1  # global plan items move with the origin: reload them
        return out + [self.mav.gps_global_origin_encode(round(self.origin.lat_deg * 1e7),
                                                        round(self.origin.lon_deg * 1e7),
                                                        round(self.origin.alt_amsl_m * 1000.0))]

    def orbit(self, o: GlobalOrbit) -> Verdict:
        """MAV_CMD_DO_ORBIT: the centre and altitude about the global origin (NaN stays NaN: the mode resolves it), to
        the vehicle, which checks the circle against the operating volume once resolved."""
        n, e, d = self.to_ned(o.lat_deg, o.lon_deg, o.alt_m, o.relative_alt)
        return self._command(Orbit(OrbitRequest(o.radius_m, o.speed_m_s, o.yaw_behaviour, o.sweep_rad, (n, e), d)))

    def reposition(self, lat_deg: float, lon_deg: float, alt_m: float, relative_alt: bool, yaw_rad: float) -> Verdict:
        """MAV_CMD_DO_REPOSITION to a global point: checked against the operating volume (VOL_*), refused, never
        flown, outside it."""
        pos = self.to_ned(lat_deg, lon_deg, alt_m, relative_alt)
        if why := self.position_problem(pos):
            return False, f"Reposition refused: {why}"
        return self._vehicle.command(Reposition(pos, yaw_rad))

    def to_ned(self, lat_deg: float, lon_deg: float, alt_m: float, relative_alt: bool) -> tuple[float, float, float]:
        """A WGS-84 point around the global origin (NaN stays NaN); alt AMSL, or above home when relative_alt."""
        n, e = self.origin.to_ned_xy(lat_deg, lon_deg)
        d = self._home_z() - alt_m if relative_alt else self.origin.alt_amsl_m - alt_m
        return n, e, d

    def above_home_m(self, alt_amsl_m: float) -> float:
        """An altitude above mean sea level as a height above home (NaN stays NaN)."""
        return self._home_z() - (self.origin.alt_amsl_m - alt_amsl_m)

    def volume(self) -> OperatingVolume:
        """The operating volume in force (VOL_*), typed again only after a parameter change."""
        reg = self._registry
        if reg.generation != self._volume_generation:
            self._volume, self._volume_generation = OperatingVolume.from_params(reg), reg.generation
        return self._volume

    def position_problem(self, pos_ned_m: tuple[float, float, float]) -> str:
        """Why a position target (DO_REPOSITION's) leaves the operating volume ('' when it does not; NaN: not
        given, the vehicle's own)."""
        return self.volume().target_problem(pos_ned_m, (0.0, 0.0, 0.0), self._home())

    def item_problem(self, item: MissionItem, mission_type: int) -> Problem | None:
        """Why an uploaded mission or rally item leaves the operating volume (None: it does not)."""
        if mission_type not in (MissionType.MISSION, MissionType.RALLY):
            return None
        return self.volume().item_problem(item, self.origin, self._home())

    def _home(self) -> tuple[float, float, float]:
        home = self._state().home_ned_m
        return tuple(home) if home is not None else (0.0, 0.0, 0.0)  # type: ignore[return-value]

    def _home_z(self) -> float:
        home = self._state().home_ned_m
        return home[2] if home is not None else 0.0
