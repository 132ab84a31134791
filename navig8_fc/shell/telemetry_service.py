"""The GCS service's telemetry: the streams a ground station gets on the wall clock (each peer that sets its own
rates gets its own table), built from a snapshot of the vehicle's latest state only when something is due
(navig8_fc/gcs/telemetry.py builds the messages; docs/gcs.md, "Telemetry")."""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Hashable, Mapping
from dataclasses import dataclass
from typing import Any

from navig8_fc.core.k_xi import eig_margin_lower_bound
from navig8_fc.core.vehicle import VehicleConfig
from navig8_fc.flight.stack import throttle_pct
from navig8_fc.flight.state import VehicleState
from navig8_fc.gcs.telemetry import (
    TelemetryBuilder,
    TelemetryScheduler,
    VehicleSnapshot,
    sensor_bits,
)
from navig8_fc.mission.geo import GeoOrigin, origin_from_params
from navig8_fc.params.registry import ParamRegistry, flown_k_bounds

MAV_AUTOPILOT_GENERIC, MAV_AUTOPILOT_PX4 = 0, 12  # HEARTBEAT.autopilot: the identity navig8-fc announces
Source = Hashable  # who sent a message, as the Outbox knows how to answer it (the process: (link name, address))


@dataclass(frozen=True)
class TelemetrySettings:
    """The telemetry's parameters, typed once per parameter change (Telemetry.settings)."""

    k_min: float  # the box of the K the INDI flies (registry.flown_k_bounds: INDI_K_MIN..MAX with INDI_LAM_REF and
    k_max: float  # INDI_KFL_MIN), which the eigenvalue margin is bounded over
    k_flown_floor: float  # INDI_KFL_MIN, or the automatic link floor when higher (registry.flown_values)
    battery_low_pct: float  # FS_BAT_LOW_PCT: below it SYS_STATUS's battery is unhealthy (the low-battery failsafe)
    origin: GeoOrigin  # ORIGIN_*: the global origin of GLOBAL_POSITION_INT, HOME_POSITION, ...

    @staticmethod
    def from_params(values: Mapping[str, float]) -> TelemetrySettings:
        return TelemetrySettings(*flown_k_bounds(values), float(values["INDI_KFL_MIN"]),
                                 float(values["FS_BAT_LOW_PCT"]), origin_from_params(values))


class Telemetry:
    """Streams on the wall clock from a snapshot of the vehicle's latest state (built only when something is due)."""

    MAX_PEER_TABLES = 8  # as many as a link keeps peers
    EIG_MARGIN_PERIOD_S = 0.5  # the bound-based margin costs ~1.4 ms: refresh it at 2 Hz

    def __init__(self, mav: Any, sysid: int, state: Callable[[], VehicleState], registry: ParamRegistry,
                 vehicle_config: VehicleConfig, autopilot: int = MAV_AUTOPILOT_GENERIC) -> None:
        self._state = state
        self._registry = registry
        self._vehicle = vehicle_config
        self.scheduler = TelemetryScheduler()  # the shared stream table (defaults and SET_MESSAGE_INTERVAL
        # from in-process callers); peers that set their own rates get a copy (scheduler_for)
        self._peer_sched: dict[Source, TelemetryScheduler] = {}
        # Announced as PX4 (option), QGroundControl's PX4 plugin wants flight_sw_version >= 1.4.1 and warns about
        # an old release when the type is OFFICIAL: 1.15.0 DEV (docs/gcs.md, "Autopilot identity").
        sw = (1, 15, 0) if autopilot == MAV_AUTOPILOT_PX4 else (0, 1, 0)
        self.builder = TelemetryBuilder(mav, sysid, 1, autopilot=autopilot, sw_version=sw)
        self.boot_wall = time.monotonic()
        self.gps_off = False  # the global position source failed (an injected failure; GcsService sets it)
        self._eig_margin = math.nan
        self._eig_t = -1e9
        self._settings_generation = -1  # the registry generation `settings` was typed from
        self._settings = TelemetrySettings.from_params(registry.flown_values())

    @property
    def settings(self) -> TelemetrySettings:
        """The parameters in force, typed again only after a change."""
        reg = self._registry
        if reg.generation != self._settings_generation:
            self._settings = TelemetrySettings.from_params(reg.flown_values())
            self._settings_generation = reg.generation
        return self._settings

    def snapshot(self, now_wall: float) -> VehicleSnapshot:
        v = self._state()
        s = v.sensors
        st = v.status
        cfg = self.settings
        stab = self._registry.stability_status()
        # the floor's lambda_crit: the loop flown (over a late sim link, that link's); lockstep's H(s) while computing
        lam_crit = stab.lambda_crit if stab is not None else v.lambda_crit
        if st is not None and now_wall - self._eig_t > self.EIG_MARGIN_PERIOD_S:
            self._eig_t = now_wall
            self._eig_margin = eig_margin_lower_bound(self._vehicle, st.q_est_rad, cfg.k_min, cfg.k_max, lam_crit)
        zero3 = (0.0, 0.0, 0.0)
        ok = v.sensors_ok
        return VehicleSnapshot(
            armed=v.armed,
            base_mode=v.base_mode,
            custom_mode=v.custom_mode,
            system_status=v.system_status,
            landed_state=v.landed_state,
            pos_ned_m=s.pos_ned_m if s else zero3,
            vel_ned_m_s=s.vel_ned_m_s if s else zero3,
            quat_wxyz=s.quat_wxyz if s else (1.0, 0.0, 0.0, 0.0),
            gyro_frd_rad_s=s.gyro_frd_rad_s if s else zero3,
            accel_frd_m_s2=s.accel_frd_m_s2 if s else zero3,
            state_valid=s is not None,  # no made-up pose before the first sensor data
            home_ned_m=v.home_ned_m,
            home_yaw_rad=v.home_yaw_rad,
            battery=v.battery,
            duct_tilt_rad=s.duct_tilt_rad if s else (0.0, 0.0),
            prop_speed_rad_s=s.prop_speed_rad_s if s else zero3,
            joint_pos_rad=s.joint_pos_rad if s else zero3,
            gripper_closed=s.gripper_closed if s else False,
            origin=cfg.origin,
            sensors=sensor_bits(imu_ok=ok, pose_ok=ok, actuators_ok=ok, estimator_ok=st is not None,
                                battery_ok=v.battery.remaining_pct > cfg.battery_low_pct, prearm_ok=bool(v.prearm.ok),
                                gps_ok=not self.gps_off),
            ckf_x_hat=st.adapt.x_hat if st else (math.nan,) * 4,  # type: ignore[arg-type]
            ckf_k=st.adapt.k if st else (math.nan,) * 4,  # type: ignore[arg-type]
            eig_margin=self._eig_margin,
            lam_crit=lam_crit,
            lam_margin=stab.margin if stab is not None else math.nan,
            kfl_flown=cfg.k_flown_floor,
            time_unix_usec=time.time_ns() // 1000,
            throttle_pct=throttle_pct(self._vehicle, s.prop_speed_rad_s) if s else 0.0,
            orbit=v.orbit,
            gps_ok=not self.gps_off,
        )

    def boot_ms(self, now_wall: float) -> int:
        return int((now_wall - self.boot_wall) * 1000)

    def scheduler_for(self, source: Source | None, create: bool = False) -> TelemetryScheduler:
        """The stream table of one peer (as PX4 keeps one per link, but per peer: a SET_MESSAGE_INTERVAL from one
        ground station changes only the rates it receives; docs/security.md). Without a table of its own a peer
        gets the shared defaults; `create` gives it one (a copy of the defaults), at most MAX_PEER_TABLES, the
        oldest dropped (that peer falls back to the shared table)."""
        if source is None:
            return self.scheduler
        sched = self._peer_sched.get(source)
        if sched is None:
            if not create:
                return self.scheduler
            if len(self._peer_sched) >= self.MAX_PEER_TABLES:
                del self._peer_sched[next(iter(self._peer_sched))]
            sched = self._peer_sched[source] = self.scheduler.copy()
        return sched

    @property
    def peers_with_own_rates(self) -> frozenset[Source]:
        return frozenset(self._peer_sched)

    def due_messages(self, now_wall: float) -> list[Any]:
        """The shared table's streams that are due (for every peer without a table of its own)."""
        due = self.scheduler.due(now_wall)
        if not due:
            return []
        return self.builder.build_many(due, self.snapshot(now_wall), self.boot_ms(now_wall))

    def due_per_peer(self, now_wall: float) -> list[tuple[Source, list[Any]]]:
        """Each peer table's due streams (the snapshot built once for all of them)."""
        out: list[tuple[Source, list[Any]]] = []
        snap = None
        for source, sched in self._peer_sched.items():
            due = sched.due(now_wall)
            if due:
                snap = snap or self.snapshot(now_wall)
                out.append((source, self.builder.build_many(due, snap, self.boot_ms(now_wall))))
        return out

    def build_now(self, msg_id: int, now_wall: float) -> list[Any] | None:
        if msg_id not in self.builder.supported_ids:
            return None
        return self.builder.build(msg_id, self.snapshot(now_wall), self.boot_ms(now_wall))
