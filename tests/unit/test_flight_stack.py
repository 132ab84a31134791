"""FlightStack at its public boundary: step() results, VehicleCommands, check_links() failsafe inputs, state().

The failsafe decisions were shell code before; here they are inputs (link ages measured on the caller's clock)
and the expected outcomes are PX4's: a lost GCS lands a vehicle flying a GCS-commanded mode, never a scripted
mission, and a GCS that never connected is never lost. The in-process loop (navig8-sim) and navig8-fc drive this
object; `test_stack_flies_the_script_as_the_scripted_core_did` checks it commands what the pre-stack in-process
loop commanded (the script's setpoint, engaged), bit for bit, in closed loop with the plant."""

from __future__ import annotations

import math

import numpy as np
import pytest

from navig8_fc.core import vehicle as vm
from navig8_fc.core.controller import ControllerConfig, FcSensors, FlightControllerCore
from navig8_fc.flight import ArmRequest, FlightStack, Notice, load_flight_script, rotor_thrusts_n
from navig8_fc.flight.commands import Arm, ArmJoints, Gripper, LoadFence, OffboardSetpoint, SetMode, Takeoff
from navig8_fc.flight.state import SEVERITY_CRITICAL, SEVERITY_ERROR, SEVERITY_INFO, SEVERITY_WARNING
from navig8_fc.modes import FlightMode
from navig8_fc.params.registry import ParamRegistry

DT_US = 10_000


@pytest.fixture(scope="module")
def vehicle() -> vm.VehicleConfig:
    return vm.VehicleConfig.load()


def _hover_speed(vehicle: vm.VehicleConfig, thrust_ratio: float) -> float:
    """Duct speed at which the two ducts carry thrust_ratio x the weight (tail idle)."""
    return math.sqrt(thrust_ratio * vehicle.uam_mass_kg * vehicle.gravity_m_s2 / (2.0 * vehicle.k_thrust_duct))


def _sensors(t_us: int, z_ned_m: float, duct_speed: float, n_ned_m: float = 0.0) -> FcSensors:
    return FcSensors(t_s=t_us * 1e-6, gyro_frd_rad_s=(0.0, 0.0, 0.0), accel_frd_m_s2=(0.0, 0.0, -9.81),
                     pos_ned_m=(n_ned_m, 0.0, z_ned_m), vel_ned_m_s=(0.0, 0.0, 0.0), quat_wxyz=(1.0, 0.0, 0.0, 0.0),
                     duct_tilt_rad=(0.0, 0.0), prop_speed_rad_s=(duct_speed, 0.0, duct_speed), joint_pos_rad=(0.0,
                                                                                                              0.0, 0.0),
                     joint_rate_rad_s=(0.0, 0.0, 0.0))


class Feed:
    """Steps a stack at 100 Hz with a vehicle resting on the ground or hovering at 2 m."""

    def __init__(self, stack: FlightStack, vehicle: vm.VehicleConfig, in_air: bool) -> None:
        self.stack, self.t_us = stack, 0
        self.z, self.w = (-2.0, _hover_speed(vehicle, 1.0)) if in_air else (0.0, 0.0)
        self.n = 0.0  # north of the start (m)

    def run(self, n: int, dt_us: int = DT_US) -> list[Notice]:
        notices: list[Notice] = []
        for _ in range(n):
            notices += self.stack.step(_sensors(self.t_us, self.z, self.w, self.n), True, self.t_us).notices
            self.t_us += dt_us
        return notices


def _hovering_in_hold(vehicle: vm.VehicleConfig) -> tuple[FlightStack, Feed]:
    """No script; a GCS forced the arm in the air: Hold (a GCS-commanded mode)."""
    stack = FlightStack(vehicle, ParamRegistry.from_defaults())
    feed = Feed(stack, vehicle, in_air=True)
    feed.run(60)
    assert stack.command(Arm(force=True)).ok
    feed.run(1)
    assert stack.state().flight_mode is FlightMode.HOLD and not stack.state().landed
    return stack, feed


def test_a_gcs_that_never_connected_never_triggers_gcs_loss(vehicle) -> None:
    stack, feed = _hovering_in_hold(vehicle)
    for _ in range(100):  # any length of time without a heartbeat ever
        assert stack.check_links(0.0, None) == ()
        feed.run(1)
    st = stack.state()
    assert st.flight_mode is FlightMode.HOLD and not st.gcs_lost and st.armed


def test_gcs_loss_lands_a_vehicle_in_a_gcs_commanded_mode_once_and_regains(vehicle) -> None:
    stack, feed = _hovering_in_hold(vehicle)
    tout = float(stack.registry["FS_GCS_TOUT"])
    assert stack.check_links(0.0, tout - 0.01) == ()
    assert stack.check_links(0.0, tout + 0.01) == (Notice(SEVERITY_WARNING, "GCS link lost: landing"),)
    feed.run(1)
    st = stack.state()
    assert st.flight_mode is FlightMode.LAND and st.gcs_lost
    assert stack.check_links(0.0, tout + 1.0) == ()  # decided once per loss
    assert stack.check_links(0.0, 0.1) == (Notice(SEVERITY_INFO, None, "GCS link regained"),)
    assert not stack.state().gcs_lost


@pytest.mark.parametrize("case", ["scripted mission", "on the ground"])
def test_gcs_loss_only_logs_in_a_mission_or_on_the_ground(vehicle, case: str) -> None:
    if case == "scripted mission":
        stack = FlightStack(vehicle, ParamRegistry.from_defaults(), load_flight_script("hover"))
        feed = Feed(stack, vehicle, in_air=True)
        mode = FlightMode.MISSION
    else:
        stack = FlightStack(vehicle, ParamRegistry.from_defaults())
        feed = Feed(stack, vehicle, in_air=False)
        mode = FlightMode.READY
    feed.run(60)
    if case == "on the ground":
        assert stack.command(Arm()).ok
        feed.run(1)
    got = stack.check_links(0.0, float(stack.registry["FS_GCS_TOUT"]) + 1.0)
    assert got == (Notice(SEVERITY_WARNING, None, "GCS link lost"),)
    feed.run(1)
    assert stack.state().flight_mode is mode and stack.state().armed


def test_stale_sensors_fail_prearm_once_per_outage_and_clear(vehicle) -> None:
    stack = FlightStack(vehicle, ParamRegistry.from_defaults())
    feed = Feed(stack, vehicle, in_air=False)
    assert stack.check_links(None, None) == ()  # before the first bundle: nothing to be stale
    feed.run(60)
    assert stack.state().prearm.ok and stack.state().sensors_ok
    tout = float(stack.registry["FS_SENS_TOUT"])
    (lost,) = stack.check_links(tout + 0.1, None)
    assert lost.severity == SEVERITY_CRITICAL
    assert lost.statustext == f"No sensor data from navig8-bridge for {tout:.1f} s"
    assert lost.event is not None and "last step t = 0.590 s" in lost.event
    assert stack.check_links(tout + 0.7, None) == ()  # one report per outage
    st = stack.state()
    assert not st.sensors_ok and not st.prearm.ok and "navig8-bridge" in st.prearm.reason
    ok, why = stack.command(Arm(False))
    assert not ok and "navig8-bridge" in why
    (back,) = stack.check_links(0.01, None)
    assert back.severity == SEVERITY_INFO and back.statustext == "Sensor data from navig8-bridge back after 1.2 s"
    assert stack.state().sensors_ok and stack.state().prearm.ok


def test_control_rate_mismatch_is_reported_once_and_clears(vehicle) -> None:
    reg = ParamRegistry.from_defaults()
    stack = FlightStack(vehicle, reg)
    feed = Feed(stack, vehicle, in_air=False)
    assert feed.run(60) == []
    assert reg.set("INDI_RATE_HZ", 200).accepted  # the bundles keep coming every 10 ms
    got = feed.run(5)
    assert len(got) == 1 and got[0].severity == SEVERITY_ERROR
    assert got[0].statustext == got[0].event == (
        "Control rate mismatch: navig8-bridge steps 10 ms, INDI_RATE_HZ 200 needs 5 ms; "
        "fix: navig8-bridge --dt 0.005 or restore INDI_RATE_HZ 100")
    assert not stack.state().prearm.ok and "INDI_RATE_HZ 200" in stack.state().prearm.reason
    assert feed.run(3, dt_us=5_000) == [Notice(SEVERITY_INFO, "Control rate matches navig8-bridge again (5 ms)",
                                                "Control rate matches navig8-bridge again (5 ms)")]
    assert stack.state().faults == ()


def test_arm_and_gripper_requests_reach_the_next_step_merged(vehicle) -> None:
    stack = FlightStack(vehicle, ParamRegistry.from_defaults())
    feed = Feed(stack, vehicle, in_air=False)
    feed.run(1)
    assert stack.command(Gripper("grab")).ok and stack.command(ArmJoints((0.1, 0.2, -0.3))).ok
    assert stack.state().pending_arm_request == ArmRequest((0.1, 0.2, -0.3), "grab")
    res = stack.step(_sensors(feed.t_us, 0.0, 0.0), True, feed.t_us)
    assert res.arm_request == ArmRequest((0.1, 0.2, -0.3), "grab")
    assert stack.step(_sensors(feed.t_us + DT_US, 0.0, 0.0), True, feed.t_us + DT_US).arm_request is None
    lim = vehicle.joint_limit_rad
    assert not stack.command(ArmJoints((lim + 0.01, 0.0, 0.0))).ok
    assert not stack.command(ArmJoints((math.nan, 0.0, 0.0))).ok
    assert stack.state().pending_arm_request is None


def test_commands_answer_and_mode_events_come_with_the_next_step(vehicle) -> None:
    stack = FlightStack(vehicle, ParamRegistry.from_defaults())
    feed = Feed(stack, vehicle, in_air=False)
    ok, why = stack.command(Arm(False))
    assert not ok and why == "Arming denied: no sensor data yet"
    feed.run(10)
    ok, why = stack.command(Arm(False))
    assert not ok and why == "Arming denied: estimator not ready"  # ESTIMATOR_WARMUP_S of steps first
    feed.run(50)
    assert stack.command(Arm(False)).ok and stack.state().armed
    assert feed.run(1) == [Notice(SEVERITY_INFO, "Armed")]
    assert stack.command(Takeoff(2.0)).ok
    res = stack.step(_sensors(feed.t_us, 0.0, 0.0), True, feed.t_us)
    assert res.engaged and res.armed and Notice(SEVERITY_INFO, "Takeoff to 2.0 m above home") in res.notices


def test_rotor_thrusts_match_the_propulsion_wrench(vehicle) -> None:
    """Independent check: each rotor's thrust is the magnitude of its force in vehicle.propulsion_wrench (the
    vector-form model of Sec. 3), signed by the tail's direction of spin."""
    rng = np.random.default_rng(3)
    for _ in range(20):
        a1, a3 = rng.uniform(-1.0, 1.0, 2)
        w1, w2, w3 = rng.uniform(0.0, 900.0), rng.uniform(-300.0, 300.0), rng.uniform(0.0, 900.0)
        u = vm.actuators_to_u(a1, a3, w1, w2, w3)
        per_rotor = []
        for cols in ((0, 1), (4,), (2, 3)):
            ui = np.zeros(5)
            ui[list(cols)] = u[list(cols)]
            f, _ = vm.propulsion_wrench(vehicle, ui)
            per_rotor.append(float(np.linalg.norm(f)))
        per_rotor[1] *= math.copysign(1.0, w2)
        np.testing.assert_allclose(rotor_thrusts_n(vehicle, (w1, w2, w3)), per_rotor, rtol=1e-12)


def test_battery_discharges_with_the_hover_load(vehicle) -> None:
    stack = FlightStack(vehicle, ParamRegistry.from_defaults())
    feed = Feed(stack, vehicle, in_air=True)
    feed.run(101)  # 1 s of hover thrust
    b = stack.state().battery
    t = vehicle.uam_mass_kg * vehicle.gravity_m_s2 / 2.0  # per duct
    power_w = 2.0 * t**1.5 / (math.sqrt(2 * 1.225 * 0.07) * 0.6)  # momentum theory, FM 0.6 (docs/gcs.md)
    assert b.energy_j == pytest.approx(power_w * 1.0, rel=1e-3)


def test_stack_flies_the_script_as_the_scripted_core_did(vehicle) -> None:
    """Closed loop with the plant on the paper scenario: the stack's setpoint is the script's and its command is
    what a bare core commands with that setpoint, engaged (the in-process loop before the stack), bit for bit."""
    from navig8_tools.sim import sensors_to_fc
    from sim_bridge.messages import ActuatorCommand
    from sim_bridge.params import PlantParams
    from sim_bridge.plant import Plant
    from sim_bridge.scenario import load_scenario

    reg = ParamRegistry.from_defaults()
    sc = load_scenario("paper")
    plant = Plant(vehicle, PlantParams.load(), sc, np.random.default_rng(1))
    stack = FlightStack(vehicle, reg, sc.script)
    bare = FlightControllerCore(vehicle, ControllerConfig.from_params(reg.as_dict(), vehicle))
    texts = []
    for _ in range(700):  # 7 s: the arm's ramp, two square-wave edges, the mass step and the first setpoint step
        sb = plant.sense()
        s = sensors_to_fc(sb)
        res = stack.step(s, True, sb.time_us)
        sp = sc.script.setpoint_at(s.t_s)
        cmd, st = bare.step(s, sp, engaged=True)
        assert res.setpoint == sp and res.engaged and res.armed
        assert res.command == cmd and repr(res.status) == repr(st)  # repr: NaN fields compare equal
        texts += [n.statustext for n in res.notices]
        plant.step(ActuatorCommand(tilt_rad=cmd.tilt_rad, speed_rad_s=cmd.speed_rad_s), 0.01)
    assert texts == ["Mission paper started (armed in the air)"]


def test_offboard_setpoint_loss_holds_after_fs_offb_tout(vehicle) -> None:
    from navig8_fc.core.outer_loop import Setpoint
    from navig8_fc.modes.px4 import px4_custom_mode

    stack, feed = _hovering_in_hold(vehicle)
    here = stack.state().setpoint
    assert not stack.command(SetMode(1, px4_custom_mode(6, 0))).ok  # no stream yet
    assert stack.command(OffboardSetpoint(Setpoint(here.pos_ned_m, 0.0, here.yaw_rad))).ok
    assert not stack.command(OffboardSetpoint(Setpoint((math.nan, 0.0, 0.0), 0.0, 0.0))).ok
    assert stack.command(SetMode(1, px4_custom_mode(6, 0))).ok
    feed.run(1)
    assert stack.state().flight_mode is FlightMode.OFFBOARD
    tout = float(stack.registry["FS_OFFB_TOUT"])
    assert stack.check_links(0.0, None, tout - 0.01) == ()
    (lost,) = stack.check_links(0.0, None, tout + 0.1)
    assert lost.severity == SEVERITY_WARNING and "Offboard setpoints lost" in lost.statustext
    feed.run(1)
    assert stack.state().flight_mode is FlightMode.HOLD
    assert stack.check_links(0.0, None, tout + 1.0) == ()  # once per loss


@pytest.mark.parametrize("action, mode, verb", [(0, FlightMode.HOLD, "no action"), (1, FlightMode.HOLD, "holding"),
                                                (2, FlightMode.LAND, "landing"), (3, FlightMode.RTL, "returning")])
def test_gcs_loss_runs_the_configured_action(vehicle, action: int, mode: FlightMode, verb: str) -> None:
    stack, feed = _hovering_in_hold(vehicle)
    stack.registry.set("FS_GCS_ACT", action)
    (n,) = stack.check_links(0.0, float(stack.registry["FS_GCS_TOUT"]) + 0.1)
    assert n == Notice(SEVERITY_WARNING, f"GCS link lost: {verb}")
    feed.run(1)
    st = stack.state()
    assert st.flight_mode is mode and st.failsafes == ("GCS link lost",) and st.system_status == 5  # CRITICAL


@pytest.mark.parametrize("action, mode", [(1, FlightMode.HOLD), (2, FlightMode.LAND), (3, FlightMode.RTL)])
def test_battery_critical_runs_the_configured_action_once(vehicle, action: int, mode: FlightMode) -> None:
    stack, feed = _hovering_in_hold(vehicle)
    stack.registry.set("FS_BAT_CRIT_ACT", action)
    stack.registry.set("FS_BAT_LOW_PCT", 100.0)
    stack.registry.set("FS_BAT_CRIT_PCT", 100.0)  # the full pack is at 100 %: at or below
    notices = [n for _ in range(50) for n in feed.run(1)]  # 0.5 s: five battery updates
    texts = [n.statustext for n in notices if n.statustext and "Battery" in n.statustext]
    assert len(texts) == 1 and texts[0].startswith("Battery critical") and stack.state().flight_mode is mode


def test_fence_breach_radius_altitude_and_uploaded_circle(vehicle) -> None:
    from navig8_fc.mission.geo import GeoOrigin
    from navig8_fc.mission.plan import Cmd, Frame, MissionItem, Plan

    stack, feed = _hovering_in_hold(vehicle)
    home = stack.state().home_ned_m
    stack.registry.set("FS_FENCE_ACT", 2)
    stack.registry.set("FENCE_ALT_MAX", 0.5)
    feed.z -= 1.0  # 1 m above home (armed where it hovered)
    texts = [n.statustext for _ in range(2) for n in feed.run(1) if n.statustext]
    assert any(t.startswith("Fence breach") and "above home" in t and t.endswith("landing") for t in texts), texts
    assert stack.state().flight_mode is FlightMode.LAND
    # Uploaded zones: an inclusion circle of 10 m around home, an exclusion circle 30 m north; and two zones on the
    # wrong side of home (an inclusion circle 50 m away, an exclusion circle around home), which PX4 drops.
    stack2, feed2 = _hovering_in_hold(vehicle)
    origin = GeoOrigin()

    def circle(cmd: Cmd, north_m: float, radius_m: float) -> MissionItem:
        lat, lon, _ = origin.to_global((home[0] + north_m, home[1], 0.0))
        return MissionItem(Frame.GLOBAL_INT, cmd, 1, radius_m, 0, 0, 0, round(lat * 1e7), round(lon * 1e7), 0.0)

    inc, exc = Cmd.NAV_FENCE_CIRCLE_INCLUSION, Cmd.NAV_FENCE_CIRCLE_EXCLUSION
    fence = Plan(1, (circle(inc, 0.0, 10.0), circle(exc, 30.0, 5.0), circle(inc, 50.0, 10.0), circle(exc, 0.0, 3.0)))
    assert stack2.command(LoadFence(fence, origin)).ok
    texts = [n.statustext for n in feed2.run(10) if n.statustext]
    assert texts == ["Geofence: 2 zone(s) on the wrong side of home, not enforced"], texts  # told once, no breach
    feed2.n = 8.0  # inside every enforced zone (and 5 m outside the dropped exclusion circle around home)
    assert not [n for n in feed2.run(5) if n.statustext]
    feed2.n = 12.0  # outside the inclusion circle around home
    texts = [n.statustext for n in feed2.run(1) if n.statustext]
    assert any("inclusion circle" in t and t.endswith("holding") for t in texts), texts
    # The exclusion zone 30 m north, on its own
    stack3, feed3 = _hovering_in_hold(vehicle)
    assert stack3.command(LoadFence(Plan(1, (circle(Cmd.NAV_FENCE_CIRCLE_EXCLUSION, 30.0, 5.0),)), origin)).ok
    feed3.n = 20.0
    assert not [n for n in feed3.run(5) if n.statustext]
    feed3.n = 28.0
    texts = [n.statustext for n in feed3.run(1) if n.statustext]
    assert any("exclusion circle" in t and t.endswith("holding") for t in texts), texts
