"""Every failsafe decision of the FC in one place, from inputs the shell and the step hand in (docs/gcs.md,
"Failsafes"): sensor validity (invalid sensor data for BAD_DATA_FAILSAFE_S: land), sensor staleness (a fault:
no arming, HEARTBEAT CRITICAL), the control-rate check (the bundles' spacing against INDI_RATE_HZ: a fault), a tick
that raised (land), link losses (GCS heartbeat, offboard stream), battery and fence. Each acts through the mode
manager (hold, land, return, faults) and says so with a `Notice`; the names in force go to HEARTBEAT/SYS_STATUS.
Pure: no clocks (ages and times come in), no I/O.

Failsafes and faults (STATUSTEXT texts are part of the interface: docs/gcs.md):
- sensor data stale: no bundle for FS_SENS_TOUT (the shell's wall clock: lockstep has no sim time without
  bundles) -> CRITICAL notice once per outage, pre-arm fails, an armed vehicle reports MAV_STATE_CRITICAL;
  cleared (INFO notice) when bundles arrive again. The vehicle cannot be commanded without bundles;
- failsafe actions (parameters FS_*_ACT: 0 none, 1 hold, 2 land, 3 return, Return falling back to Land): each
  says `<what>: <holding|landing|returning|no action>` (STATUSTEXT WARNING) and, while in force, HEARTBEAT
  system_status is CRITICAL (armed) and SYS_STATUS's battery bit is unhealthy below FS_BAT_LOW_PCT;
- offboard setpoints lost: none for FS_OFFB_TOUT (wall clock) -> Offboard can no longer be entered, a vehicle in
  Offboard holds where it is, then FS_OFFB_ACT (PX4's COM_OF_LOSS_T / COM_OBL_RC_ACT);
- battery low / critical: remaining below FS_BAT_LOW_PCT / FS_BAT_CRIT_PCT while flying -> FS_BAT_LOW_ACT /
  FS_BAT_CRIT_ACT, once each;
- fence breach: outside an uploaded inclusion circle/polygon, beyond FENCE_RADIUS or above FENCE_ALT_MAX from
  home while flying -> FS_FENCE_ACT, once per breach (navig8_fc.mission.fence);
- GCS link lost: a ground station that sent heartbeats goes silent for FS_GCS_TOUT while the vehicle is armed
  in the air in a GCS-commanded mode (not a mission) -> FS_GCS_ACT (default land; PX4's data-link-loss failsafe); a GCS
  that never sent a heartbeat is never lost;
- control-rate mismatch: RATE_MISMATCH_STEPS bundle spacings in a row that are not 1/INDI_RATE_HZ -> ERROR
  notice once, pre-arm fails until the spacings agree again (the filters, rate limits and the stability
  analysis all assume 1/INDI_RATE_HZ).
- invalid sensor data (the sim guard's validation, navig8_fc/links/sim_guard.py) for BAD_DATA_FAILSAFE_S of sim time
  -> land (CRITICAL), "Sensor data valid again" when it is;
- a control tick that raised (the shell answers with the last good command) -> land (CRITICAL), reported at the
  first error and every 100th.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

from navig8_fc.flight.battery import BatteryState
from navig8_fc.flight.state import SEVERITY_CRITICAL, SEVERITY_ERROR, SEVERITY_INFO, SEVERITY_WARNING, Notice
from navig8_fc.mission.fence import Fence
from navig8_fc.modes.manager import ModeManager
from navig8_fc.modes.px4 import FlightMode

FS_NONE, FS_HOLD, FS_LAND, FS_RETURN = 0, 1, 2, 3  # FS_*_ACT values
FAULT_SENSORS = "sensors"  # ModeManager fault names
FAULT_RATE = "rate"
RATE_MISMATCH_STEPS = 3  # consecutive bundle spacings != 1/INDI_RATE_HZ before it is reported (not a glitch)
BAD_DATA_FAILSAFE_S = 0.2  # sim s of continuously invalid sensor data (the sim guard's count) before landing


@dataclass(frozen=True)
class FailsafeSettings:
    """The failsafes' parameters, typed once per parameter change."""

    sensor_timeout_s: float  # FS_SENS_TOUT
    gcs_timeout_s: float  # FS_GCS_TOUT
    gcs_action: int  # FS_GCS_ACT
    offboard_timeout_s: float  # FS_OFFB_TOUT
    offboard_action: int  # FS_OFFB_ACT
    battery_low_pct: float  # FS_BAT_LOW_PCT
    battery_crit_pct: float  # FS_BAT_CRIT_PCT
    battery_low_action: int  # FS_BAT_LOW_ACT
    battery_crit_action: int  # FS_BAT_CRIT_ACT
    fence_radius_m: float  # FENCE_RADIUS
    fence_alt_max_m: float  # FENCE_ALT_MAX
    fence_action: int  # FS_FENCE_ACT
    rate_hz: int  # INDI_RATE_HZ

    @staticmethod
    def from_params(values: Mapping[str, float]) -> FailsafeSettings:
        f = {name: float(values[p]) for name, p in _FLOAT_PARAMS.items()}
        i = {name: int(values[p]) for name, p in _INT_PARAMS.items()}
        return FailsafeSettings(**f, **i)  # type: ignore[arg-type]


_FLOAT_PARAMS = {"sensor_timeout_s": "FS_SENS_TOUT", "gcs_timeout_s": "FS_GCS_TOUT",
                 "offboard_timeout_s": "FS_OFFB_TOUT", "battery_low_pct": "FS_BAT_LOW_PCT",
                 "battery_crit_pct": "FS_BAT_CRIT_PCT", "fence_radius_m": "FENCE_RADIUS",
                 "fence_alt_max_m": "FENCE_ALT_MAX"}
_INT_PARAMS = {"gcs_action": "FS_GCS_ACT", "offboard_action": "FS_OFFB_ACT", "battery_low_action": "FS_BAT_LOW_ACT",
               "battery_crit_action": "FS_BAT_CRIT_ACT", "fence_action": "FS_FENCE_ACT", "rate_hz": "INDI_RATE_HZ"}


class Failsafes:
    """The failsafe state of one flight stack (module docstring); acts on `modes`."""

    def __init__(self, modes: ModeManager, settings: FailsafeSettings, sensor_source: str) -> None:
        self._modes = modes
        self._source = sensor_source  # named in the sensor and rate notices
        self._in_force: set[str] = set()  # failsafes in force (battery, fence, link losses)
        self._sensors_stale = False
        self._stale_age_s = 0.0  # the longest sensor age seen in the current outage
        self._gcs_lost = False
        self._offboard_live = False  # offboard setpoints are arriving (newer than FS_OFFB_TOUT)
        self._bad_data = False  # the invalid-sensor-data failsafe is in force
        self._fence = Fence()
        self._fence_home: tuple[Fence, tuple[float, float, float]] | None = None  # the fence and home last told about
        self._fence_on = False  # a fence to check: FENCE_RADIUS, FENCE_ALT_MAX or an uploaded plan
        self._battery_checked: BatteryState | None = None  # the pack state the battery check last looked at
        self._dt_bad_n = 0  # consecutive bundle spacings that disagree with 1/INDI_RATE_HZ
        self.configure(settings)

    def configure(self, settings: FailsafeSettings) -> None:
        self.settings = settings
        step_us = 1e6 / settings.rate_hz  # the bundle spacing this rate needs
        self._dt_lo_us, self._dt_hi_us = math.floor(step_us), math.ceil(step_us)
        self._fence_on = self._fence_checked()

    def _fence_checked(self) -> bool:
        s, fence = self.settings, self._fence
        return bool(s.fence_radius_m > 0.0 or s.fence_alt_max_m > 0.0 or fence.has_zones)

    @property
    def in_force(self) -> tuple[str, ...]:
        """The failsafes in force (names), for HEARTBEAT/SYS_STATUS."""
        return tuple(sorted(self._in_force))

    @property
    def sensors_stale(self) -> bool:
        """No sensor bundle for FS_SENS_TOUT (the sensor fault is set)."""
        return self._sensors_stale

    @property
    def gcs_lost(self) -> bool:
        """A ground station that sent heartbeats has been silent for FS_GCS_TOUT."""
        return self._gcs_lost

    def load_fence(self, fence: Fence) -> None:
        self._fence = fence
        self._fence_on = self._fence_checked()

    # --- actions -----------------------------------------------------------------------------------------
    def act(self, name: str, action: int, detail: str = "", none_verb: str = "no action") -> Notice:
        """Run a failsafe action (0 none, 1 hold, 2 land, 3 return; PX4's numbering of NAV_DLL_ACT's useful
        subset) and say so (STATUSTEXT WARNING, `<name><detail>: <verb>`); `name` is in force from now on (HEARTBEAT
        CRITICAL while armed). Return falls back to Land when refused."""
        m = self._modes
        verb = none_verb
        if action != FS_NONE:
            m.fail_task(f"failsafe: {name}")
        if action == FS_HOLD:
            verb = "holding" if m.set_mode(4, 3).ok else verb
        elif action == FS_LAND:
            verb = "landing" if m.land().ok else verb
        elif action == FS_RETURN:
            verb = "returning" if m.set_mode(4, 5).ok else ("landing" if m.land().ok else verb)
        self._in_force.add(name)
        return Notice(SEVERITY_WARNING, f"{name}{detail}: {verb}")

    # --- inputs the step hands in ------------------------------------------------------------------------
    def spacing(self, prev_us: int | None, t_us: int) -> Notice | None:
        """The bundle spacing against 1/INDI_RATE_HZ: RATE_MISMATCH_STEPS in a row off sets the rate fault (no
        arming; the bridge's --dt disagrees with the parameter), one good spacing clears it."""
        if prev_us is not None and not self._dt_lo_us <= t_us - prev_us <= self._dt_hi_us:
            return self._spacing_off(t_us - prev_us)
        if self._dt_bad_n:
            return self._spacing_ok()
        return None

    def _spacing_off(self, d_us: int) -> Notice | None:
        if d_us <= 0:  # time went back: a restarted bridge (a new run, not a spacing)
            self._dt_bad_n = 0
            return None
        self._dt_bad_n += 1
        if self._dt_bad_n != RATE_MISMATCH_STEPS:
            return None
        rate = self.settings.rate_hz
        bridge_ms, need_ms = d_us * 1e-3, 1e3 / rate
        fix = f"{self._source} --dt {1.0 / rate:g}"
        if 1_000_000 % d_us == 0 and 20 <= 1_000_000 // d_us <= 1000:
            fix += f" or restore INDI_RATE_HZ {1_000_000 // d_us}"
        text = (f"Control rate mismatch: {self._source} steps {bridge_ms:g} ms, INDI_RATE_HZ {rate} needs "
                f"{need_ms:g} ms; fix: {fix}")
        self._modes.set_fault(FAULT_RATE, f"control rate mismatch (bridge {bridge_ms:g} ms, INDI_RATE_HZ {rate}"
                                          f" needs {need_ms:g} ms)")
        return Notice(SEVERITY_ERROR, text, text)

    def _spacing_ok(self) -> Notice | None:
        notice = None
        if self._dt_bad_n >= RATE_MISMATCH_STEPS and self._modes.clear_fault(FAULT_RATE):
            text = f"Control rate matches {self._source} again ({1e3 / self.settings.rate_hz:g} ms)"
            notice = Notice(SEVERITY_INFO, text, text)
        self._dt_bad_n = 0
        return notice

    def after_step(self, armed: bool, battery: BatteryState, pos_ned_m: tuple[float, float, float]) -> list[Notice]:
        """Battery low/critical and fence breach while armed and flying, each acting once per occurrence;
        disarmed, a new flight starts clean (the battery re-triggers if still low). Most steps have nothing to look
        at: the pack model advances every few steps, and without a fence there is nothing else."""
        if not armed:
            if self._in_force:
                self._in_force.clear()
            return []
        if battery is self._battery_checked and not self._fence_on:
            return []
        m = self._modes
        if m.landed:
            return []
        s = self.settings
        notices = []
        if battery is not self._battery_checked:  # the pack model advanced
            self._battery_checked = battery
            pct = battery.remaining_pct
            if pct <= s.battery_crit_pct and "Battery critical" not in self._in_force:
                self._in_force.add("Battery low")  # critical acts; low has nothing left to add
                notices.append(self.act("Battery critical", s.battery_crit_action, f" ({pct}% left)"))
            elif pct <= s.battery_low_pct and "Battery low" not in self._in_force:
                notices.append(self.act("Battery low", s.battery_low_action, f" ({pct}% left)"))
        home = m.home_ned_m
        fence = self._fence
        if home is None or not self._fence_on:
            return notices
        if fence.has_zones and (self._fence_home is None or self._fence_home[0] is not fence
                                or self._fence_home[1] != home):
            self._fence_home = (fence, home)  # once per fence and home: zones on the wrong side are not enforced
            k = fence.zones_not_enforced(home)
            if k:
                text = f"Geofence: {k} zone(s) on the wrong side of home, not enforced"
                notices.append(Notice(SEVERITY_CRITICAL, text, text))
        why = fence.breach(pos_ned_m, home, s.fence_radius_m, s.fence_alt_max_m)
        if why is None:
            self._in_force.discard("Fence breach")
        elif "Fence breach" not in self._in_force:
            notices.append(self.act("Fence breach", s.fence_action, f": {why}"))
        return notices

    # --- inputs the shell hands in -----------------------------------------------------------------------
    def offboard_alive(self) -> None:
        """An offboard setpoint was accepted: the stream is live."""
        self._offboard_live = True
        self._in_force.discard("Offboard setpoints lost")

    def links(self, sensor_age_s: float | None, gcs_heartbeat_age_s: float | None, offboard_age_s: float | None,
              last_step_t_s: float) -> list[Notice]:
        """Link ages measured on the shell's clock: since the last sensor bundle (None before the first), the last
        GCS heartbeat (None: no GCS ever sent one) and the last offboard setpoint (None: none yet)."""
        s = self.settings
        notices: list[Notice] = []
        if self._offboard_live and offboard_age_s is not None and offboard_age_s > s.offboard_timeout_s:
            self._offboard_live = False
            in_offboard = self._modes.flight_mode is FlightMode.OFFBOARD
            self._modes.offboard_setpoint(None)  # Offboard holds at once; then the configured action
            if in_offboard:
                notices.append(self.act("Offboard setpoints lost", s.offboard_action, f" for {offboard_age_s:.1f} s",
                                        none_verb="holding"))
        if sensor_age_s is not None:
            notices += self._sensor_age(sensor_age_s, last_step_t_s)
        if gcs_heartbeat_age_s is not None:
            notices += self._gcs_age(gcs_heartbeat_age_s)
        return notices

    def _sensor_age(self, age_s: float, last_step_t_s: float) -> list[Notice]:
        tout = self.settings.sensor_timeout_s
        if age_s > tout:
            self._stale_age_s = max(self._stale_age_s, age_s)
            if not self._sensors_stale:
                self._sensors_stale = True
                text = f"no sensor data from {self._source} for {tout:.1f} s"
                self._modes.set_fault(FAULT_SENSORS, f"sensors stale: {text}")
                return [Notice(SEVERITY_CRITICAL, text.capitalize(), f"{text} (last step t = {last_step_t_s:.3f} s); "
                                                                     "waiting")]
        elif self._sensors_stale:
            self._sensors_stale = False
            self._modes.clear_fault(FAULT_SENSORS)
            text = f"sensor data from {self._source} back after {self._stale_age_s:.1f} s"
            self._stale_age_s = 0.0
            return [Notice(SEVERITY_INFO, text.capitalize(), text)]
        return []

    def _gcs_age(self, age_s: float) -> list[Notice]:
        if age_s > self.settings.gcs_timeout_s:
            if not self._gcs_lost:
                self._gcs_lost = True
                m = self._modes
                if m.armed and m.flight_mode is not FlightMode.MISSION and not m.landed:
                    return [self.act("GCS link lost", self.settings.gcs_action)]
                return [Notice(SEVERITY_WARNING, None, "GCS link lost")]
        elif self._gcs_lost:
            self._gcs_lost = False
            self._in_force.discard("GCS link lost")
            return [Notice(SEVERITY_INFO, None, "GCS link regained")]
        return []

    def sensor_data(self, bad_groups: tuple[str, ...], bad_for_s: float) -> Notice | None:
        """The sensor groups the sim guard replaced by their last good values this step, and for how long some group
        has failed (sim s): BAD_DATA_FAILSAFE_S of it lands; valid data again is announced."""
        if not bad_groups:
            if self._bad_data:
                self._bad_data = False
                return Notice(SEVERITY_INFO, "Sensor data valid again")
            return None
        if self._bad_data or bad_for_s < BAD_DATA_FAILSAFE_S:
            return None
        self._bad_data = True
        verb = "landing" if self._modes.armed and self._modes.land().ok else "no action"
        return Notice(SEVERITY_CRITICAL, f"Bad sensor data ({','.join(bad_groups)}) {bad_for_s:.2f} s: {verb}")

    def tick_failed(self, error: str, n_errors: int) -> Notice | None:
        """The control tick raised (the shell holds the last good command): land, and say so at the first error and
        every 100th."""
        if n_errors != 1 and n_errors % 100 != 0:
            return None
        try:
            verb = "landing" if self._modes.land().ok else "holding the last command"
        except Exception:  # noqa: BLE001 - the modes themselves are failing: the held command is all there is
            verb = "holding the last command"
        return Notice(SEVERITY_CRITICAL, f"Control error {error} ({n_errors}x): {verb}")
