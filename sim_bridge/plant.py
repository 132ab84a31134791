"""The Navig8-UAM plant: UAV + 3-joint arm + object, actuators, ground contact and sensors. No I/O.

Public API (used in process by the flight-controller runner and, later, behind MAVLink by the bridge):

    from navig8_fc.core.vehicle import VehicleConfig
    from sim_bridge import ActuatorCommand, Plant, PlantParams, load_scenario

    plant = Plant(VehicleConfig.load(), PlantParams.load(), load_scenario("paper"),
                  np.random.default_rng(seed))          # base_mode="free" | "attitude_locked" | "fixed"
    cmd = plant.trim_command()                          # hover trim for the current pose and object
    plant.step(cmd, 0.01)                               # advance 10 ms, zero-order-hold command
    bundle = plant.sense()                              # SensorBundle (noisy, seeded rng)
    truth = plant.truth()                               # Truth (state, mass properties, reaction wrench)
    x = plant.state_vector                              # the state (plant_layout.X), read-only copy
    plant.truth_at(x)                                   # Truth at another state (the plant does not move)
    plant.t_us, plant.t_s                               # plant time (the lockstep master clock)

- `step(cmd, dt_s)` / `step_us(cmd, dt_us)`: dt must be a whole number of physics steps (1 ms by
  default). The command is validated once per call: a non-finite entry holds the last valid value of
  that channel, an out-of-range entry is clamped to the vehicle limits; both are counted
  (`cmd_nonfinite_count`, `cmd_clamped_count`) and neither ever reaches the state. Object events of
  the scenario (grasp, release, mass change) take effect at the first physics step at or after their
  time. `joint_targets_rad=None` follows the scenario's arm schedule.
- `sense()`: one sample at the current time. Each sensor group is sampled when its period (params)
  has elapsed, otherwise it repeats its last sample; `SensorBundle.updated` says which groups are
  fresh. Every call draws the same number of normals from the rng, so a seed fixes the run bit for bit.
- `truth()`: the frozen ground truth (see messages.Truth).
- `trim_command()`: vehicle.hover_trim for the current arm pose and object mass (level body), of the ducts as
  they are now (a duct fault, `actuators.duct_efficiency` in plant.yaml, included once it has struck).
- `command_gripper(close, object_mass_kg)`: grasp/release now (the bridge's NAVIG8_ARM_CMD gripper).

Model (notes §1-3, docs/plant.md): floating base with prescribed joint motion solved by the composite
6x6 Newton-Euler system (notes §3.4) in numba kernels (`rigid_body`, `arm_dynamics`, `actuators`,
`ground_contact`, `joint_servo`, `integrator`, `sensors`), RK4 at the physics rate with the exact
actuator and joint trajectories inside each step, exact second-order actuator discretisation, a
time-optimal rate/acceleration-limited joint servo, skid contact with the NED z = 0 ground.
"""

from __future__ import annotations

import math
from operator import itemgetter
from typing import Any, TypeVar

import numpy as np

from navig8_fc.core import rotation
from navig8_fc.core.actuator_model import actuator_discretisation
from navig8_fc.core.rotation import euler_to_quat, quat_to_euler
from navig8_fc.core.vehicle import VehicleConfig, hover_trim, propulsion_per_input, u_to_actuators
from navig8_fc.mavlink.seam import TruthFloats
from sim_bridge import sensors
from sim_bridge.command_guard import CommandGuard
from sim_bridge.integrator import N_WORK, advance, evaluate
from sim_bridge.messages import ActuatorCommand, SensorBundle, Truth, WireSensors
from sim_bridge.params import ActuatorDynamics, PlantParams
from sim_bridge.plant_layout import (
    BASE_ATTITUDE_LOCKED,
    BASE_FIXED,
    BASE_FREE,
    N_CONTACT_MAX,
    N_D,
    N_X,
    C,
    D,
    P,
    X,
)
from sim_bridge.scenario import Scenario
from sim_bridge.sensors import N_GROUPS, N_NOISE, N_S, SIG, S

_R = TypeVar("_R")
BASE_MODES = {"free": BASE_FREE, "attitude_locked": BASE_ATTITUDE_LOCKED, "fixed": BASE_FIXED}


# sense / sense_wire: the sensor vector's groups (SensorBundle's fields in order); truth_floats: TruthFloats' parts of
# the state and derived vectors (the inertia about the CoM as three rows). Cut in one C call each.
_S_GROUPS = itemgetter(*(m.sl for m in S.fields()))
_X_FLOATS = itemgetter(*(m.sl for m in (X.POS, X.VEL, X.QUAT, X.RATE, X.ACT, X.Q, X.QD, X.QDD)), int(X.MOBJ))
_D_FLOATS = itemgetter(D.ACC.sl, D.WDOT.sl, int(D.MASS), D.COM.sl,
                       *(slice(D.JC + 3 * r, D.JC + 3 * r + 3) for r in range(3)),
                       *(m.sl for m in (D.FR_G, D.MR_MOUNT_G, D.MR_O_G, D.FR_NOG, D.MR_MOUNT_NOG)))


def _fill(record: _R, **fields: Any) -> _R:
    """Set the fields of a plain record class (WireSensors, TruthFloats: attributes, no __init__, no slots), in one
    update of its instance dict (a setattr a field cost ~1.5 us a TruthFloats)."""
    record.__dict__.update(fields)
    return record


TruthState = tuple[int, bytes, bytes, int, int]  # Plant.truth_state: time_us, state, derived, guard counts


def _truth_floats(t_us: int, x: list[float], d: list[float], nonfinite: int, clamped: int) -> TruthFloats:
    pos, vel, quat, rate, act, jq, jqd, jqdd, mobj = _X_FLOATS(x)
    acc, wdot, mass, com, j0, j1, j2, fr, mr, mr_o, fr_nog, mr_nog = _D_FLOATS(d)
    return _fill(TruthFloats(), time_us=t_us, pos_ned_m=pos, vel_ned_m_s=vel, quat_wxyz=quat,
                 rate_frd_rad_s=rate, accel_frd_m_s2=acc, ang_accel_frd_rad_s2=wdot, actuator_pos=act,
                 joint_pos_rad=jq, joint_rate_rad_s=jqd, joint_accel_rad_s2=jqdd, object_mass_kg=mobj,
                 mass_kg=mass, com_frd_m=com, inertia_com_kgm2=(j0, j1, j2), reaction_force_frd_n=fr,
                 reaction_moment_mount_frd_nm=mr, reaction_moment_o_frd_nm=mr_o, reaction_force_nog_frd_n=fr_nog,
                 reaction_moment_mount_nog_frd_nm=mr_nog, cmd_nonfinite_count=nonfinite, cmd_clamped_count=clamped)


def truth_floats_of_state(state: TruthState) -> TruthFloats:
    """Plant.truth_floats() from Plant.truth_state() (the same floats: float64 bytes back to Python floats)."""
    t_us, xb, db, nonfinite, clamped = state
    return _truth_floats(t_us, np.frombuffer(xb).tolist(), np.frombuffer(db).tolist(), nonfinite, clamped)


_C_ACT = C.ACT.sl
# truth(): its views of the state and derived vectors, cut in one C call each
_TRUTH_X = itemgetter(*(m.sl for m in (X.POS, X.VEL, X.QUAT, X.RATE, X.ACT, X.ACTD, X.Q, X.QD,
                                       X.QDD, X.QTGT)))
_TRUTH_D = itemgetter(*(m.sl for m in (D.ACC, D.WDOT, D.SPF, D.COM, D.FR_G, D.MR_MOUNT_G, D.MR_O_G,
                                       D.FR_NOG, D.MR_MOUNT_NOG, D.MR_O_NOG, D.FPROP, D.MPROP, D.FCONT,
                                       D.MCONT)))
_X_MOBJ, _X_QUAT = int(X.MOBJ), X.QUAT.sl
_D_MASS, _D_NCONT, _D_JC, _D_JO = int(D.MASS), int(D.NCONT), D.JC.sl, D.JO.sl


class PlantDivergedError(RuntimeError):
    """The state became non-finite (the plant keeps the last finite state)."""


def quat_to_dcm(q: np.ndarray) -> np.ndarray:
    """R (body -> NED) from [w, x, y, z] as a 3x3 array (rotation.quat_to_dcm)."""
    return np.array(rotation.quat_to_dcm(q))


def _actuator_discretisation(dyn: ActuatorDynamics, tau_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Phi (2, 2), Gamma (2,) of y'' = wn^2 (u - y) - 2 zeta wn y' over tau with u held: the FC's actuator model's
    own exact discretisation (one copy), as the plant's integrator takes it."""
    ad, bd = actuator_discretisation(dyn.omega_n_rad_s, dyn.zeta, tau_s)
    return ad.reshape(2, 2), bd


def duct_input_scale(efficiency: tuple[float, float]) -> np.ndarray:
    """Per U component, the factor a duct fault puts on its force and moment: U1, U2 are duct 1's (right), U3, U4
    duct 3's (left), U5 the tail's. Thrust K_T w^2 and drag torque K_Q w^2 scale alike (the lost thrust takes its
    drag with it: a weaker rotor, not a draggier one), so the duct's whole column of G_C does."""
    e1, e3 = float(efficiency[0]), float(efficiency[1])
    return np.array([e1, e1, e3, e3, 1.0])


def build_param_vector(vehicle: VehicleConfig, params: PlantParams,
                       efficiency: tuple[float, float] = (1.0, 1.0)) -> np.ndarray:
    """The kernels' parameter vector (plant_layout.P); `efficiency`: the ducts' thrust factors (a fault)."""
    h = 1.0 / params.physics_rate_hz
    # Per-input force and moment about O from the FC's own propulsion model (notes §2.1-2.2), so the
    # plant and vehicle.hover_trim / G_C agree exactly; the kernel only multiplies by U. A duct fault scales its
    # columns here, the one place the plant's propulsion is built (the FC's model keeps the nominal ducts).
    f, mom = propulsion_per_input(vehicle)
    scale = duct_input_scale(efficiency)
    f, mom = f * scale, mom * scale
    dyns = (params.tilt_dynamics, params.tilt_dynamics, params.speed_dynamics, params.speed_dynamics,
            params.speed_dynamics)
    disc = {tau: [_actuator_discretisation(dyn, tau) for dyn in dyns] for tau in (h, 0.5 * h)}
    lo, hi = actuator_limits(vehicle)
    g = params.ground
    cp = np.zeros((N_CONTACT_MAX, 3))
    cp[:len(g.contact_points_frd_m)] = g.contact_points_frd_m
    return P.pack(
        g=vehicle.gravity_m_s2, m0=vehicle.uav_mass_kg, j0=vehicle.uav_inertia_array, ml=vehicle.link_mass_kg,
        ia=vehicle.link_inertia_kgm2, l=vehicle.link_length_m, mount=vehicle.mount_frd_m,
        obj_d=vehicle.object_offset_m, obj_r=vehicle.object_radius_m, pf=f, pm=mom,
        phi_h=[phi for phi, _ in disc[h]], gam_h=[gam for _, gam in disc[h]],
        phi_h2=[phi for phi, _ in disc[0.5 * h]], gam_h2=[gam for _, gam in disc[0.5 * h]],
        act_min=lo, act_max=hi, h=h, servo_n=params.servo_substeps, vmax=params.joint_v_max_rad_s,
        amax=params.joint_a_max_rad_s2, qlim=vehicle.joint_limit_rad, stall_j=params.joint_stall_index,
        stall_us=round(params.joint_stall_t_s * 1e6), kn=g.stiffness_n_m, cn=g.damping_n_s_m,
        mu=g.friction_coeff, veps=g.friction_reg_speed_m_s, nc=len(g.contact_points_frd_m), cp=cp,
        h_us=params.physics_step_us,
    )


def actuator_limits(vehicle: VehicleConfig) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper limits of (alpha1, alpha3, w1, w2, w3)."""
    lo = np.array([vehicle.tilt_min_rad, vehicle.tilt_min_rad, vehicle.duct_speed_min, vehicle.tail_speed_min,
                   vehicle.duct_speed_min])
    hi = np.array([vehicle.tilt_max_rad, vehicle.tilt_max_rad, vehicle.duct_speed_max, vehicle.tail_speed_max,
                   vehicle.duct_speed_max])
    return lo, hi


def trim_actuators(vehicle: VehicleConfig, q_rad: np.ndarray, object_mass_kg: float,
                   efficiency: tuple[float, float] = (1.0, 1.0)) -> np.ndarray:
    """(alpha1, alpha3, w1, w2, w3) of the level hover trim (vehicle.hover_trim), of ducts with these efficiencies.

    A fault scales the duct's columns of G_C, so G_C diag(s) U' = target has U' = U / s: the faulty duct's U
    components are the nominal trim's over its efficiency (its speed / sqrt(e), its tilt the same), the other
    actuators the nominal trim's."""
    u = hover_trim(vehicle, np.asarray(q_rad, dtype=float), object_mass_kg) / duct_input_scale(efficiency)
    a1, a3, w1, w2, w3 = u_to_actuators(u)
    return np.array([a1, a3, w1, w2, w3])


class Plant:
    """See the module docstring for the API."""

    def __init__(
        self,
        vehicle: VehicleConfig,
        params: PlantParams,
        scenario: Scenario,
        rng: np.random.Generator,
        *,
        base_mode: str = "free",
    ) -> None:
        if base_mode not in BASE_MODES:
            raise ValueError(f"base_mode must be one of {sorted(BASE_MODES)}")
        self.vehicle = vehicle
        self.params = params
        self.scenario = scenario
        self._rng = rng
        self._base_mode = BASE_MODES[base_mode]
        self._p = build_param_vector(vehicle, params)
        # a duct fault: the faulty propulsion from the first physics step at or after its time (from the start, and
        # trimmed for, at t = 0: the vehicle was already flying with it)
        self._fault_us: int | None = None
        self._p_fault = self._p
        self._efficiency = (1.0, 1.0)
        if params.duct_faulted:
            self._p_fault = build_param_vector(vehicle, params, params.duct_efficiency)
            self._fault_us = -(-round(params.duct_fault_t_s * 1e6) // params.physics_step_us) * params.physics_step_us
        self._h_us = params.physics_step_us
        self._sched = scenario.arm_schedule()
        self._sched[:, :2] += round(params.joint_lag_s * 1e6)  # a lagging servo: every target reached late
        self._act_lo, self._act_hi = actuator_limits(vehicle)
        self._qlim = vehicle.joint_limit_rad
        self._guard = CommandGuard(self._act_lo, self._act_hi, self._qlim)  # the command held, validated
        self._cmd = self._guard.vector
        self._d = np.zeros(N_D)
        self._work = np.zeros(N_WORK)
        # events on the physics grid: the first step at or after their time
        self._events = [
            (-(-round(ev.t_s * 1e6) // self._h_us) * self._h_us, ev) for ev in scenario.events
        ]
        self._ev_i = 0
        # sensors
        s = params.sensors
        self._sig = SIG.pack(gyro=s.gyro_sigma_rad_s, acc=s.accel_sigma_m_s2, pos=s.mocap_pos_sigma_m,
                               vel=s.mocap_vel_sigma_m_s, att=s.mocap_att_sigma_rad, duct=s.duct_tilt_sigma_rad,
                               prop=s.prop_speed_sigma_rad_s, jq=s.joint_pos_sigma_rad, jqd=s.joint_rate_sigma_rad_s,
                               gyro_bias=s.gyro_bias_rad_s, acc_bias=s.accel_bias_m_s2)
        # per group, in SensorField bit order (IMU, MOCAP, ACTUATORS, JOINTS): period and next due time (us)
        self._sensor_period_us = np.array([round(1e6 / r) for r in (s.imu_rate_hz, s.mocap_rate_hz,
                                                                     s.actuator_rate_hz, s.joint_rate_hz)],
                                          dtype=np.int64)
        self._sensor_due_us = np.zeros(N_GROUPS, dtype=np.int64)
        self._noise = np.empty(N_NOISE)  # the draws of one sample (refilled in place)
        self._meas = np.zeros(N_S)  # last sample of every sensor group (kernel-owned, writable)
        self._t_us = 0
        self._apply_due_fault()
        self._init_state(scenario)

    # ---- initial state ----------------------------------------------------------------------
    def _init_state(self, scn: Scenario) -> None:
        ini = scn.initial
        x = np.zeros(N_X)
        x[X.POS.sl] = ini.pos_ned_m
        x[X.VEL.sl] = ini.vel_ned_m_s
        quat = euler_to_quat(*ini.euler_rad)
        x[X.QUAT.sl] = quat
        if self._base_mode == BASE_FREE:
            x[X.RATE.sl] = ini.rate_frd_rad_s
        q0 = np.clip(np.array(ini.joint_pos_rad), -self._qlim, self._qlim)
        x[X.Q.sl] = q0
        x[X.QTGT.sl] = q0
        self._gripper_closed = scn.gripper_closed
        x[X.MOBJ] = scn.object_mass_kg if scn.gripper_closed else 0.0
        self._x = x
        self._apply_due_events()  # events at t = 0
        if ini.on_ground:
            self._place_on_ground()
        if ini.actuators == "trim":
            act = np.clip(trim_actuators(self.vehicle, q0, x[X.MOBJ], self._efficiency), self._act_lo,
                          self._act_hi)
        else:
            act = np.zeros(5)
        x[X.ACT.sl] = act
        self._guard.hold(act, q0)
        evaluate(self._x, self._p, self._base_mode, self._d, self._work)

    def _place_on_ground(self) -> None:
        """Skids on the ground with the static sag of the springs (the lowest contact point touches)."""
        pts = np.array(self.params.ground.contact_points_frd_m)
        if len(pts) == 0:
            raise ValueError("scenario starts on the ground but there are no contact points")
        r = quat_to_dcm(self._x[X.QUAT.sl])
        lowest = float(np.max(pts @ r[2]))
        mass = self.vehicle.uam_mass_kg + self._x[X.MOBJ]
        sag = mass * self.vehicle.gravity_m_s2 / (len(pts) * self.params.ground.stiffness_n_m)
        self._x[X.POS + 2] = -lowest + sag

    # ---- time ---------------------------------------------------------------------------------
    @property
    def t_us(self) -> int:
        return self._t_us

    @property
    def t_s(self) -> float:
        return self._t_us * 1e-6

    @property
    def physics_step_us(self) -> int:
        return self._h_us

    @property
    def cmd_nonfinite_count(self) -> int:
        return self._guard.nonfinite

    @property
    def cmd_clamped_count(self) -> int:
        return self._guard.clamped

    # ---- stepping -----------------------------------------------------------------------------
    def step(self, cmd: ActuatorCommand, dt_s: float) -> None:
        """Advance by dt_s (a whole number of physics steps) holding cmd."""
        dt_us = round(dt_s * 1e6)
        if abs(dt_us - dt_s * 1e6) > 1e-3:
            raise ValueError(f"dt_s = {dt_s} is not a whole number of microseconds")
        self.step_us(cmd, dt_us)

    def step_us(self, cmd: ActuatorCommand, dt_us: int) -> None:
        h_us = self._h_us
        if dt_us < 0 or dt_us % h_us:
            raise ValueError(f"dt = {dt_us} us is not a non-negative multiple of the physics step {h_us} us")
        self._guard.apply(cmd)
        t_end = self._t_us + dt_us
        events = self._events
        while self._t_us < t_end:
            t_stop = t_end
            pending = self._ev_i < len(events)
            if pending and events[self._ev_i][0] < t_stop:
                t_stop = events[self._ev_i][0]
            fault = self._fault_us is not None and self._fault_us <= t_stop
            if fault:
                t_stop = self._fault_us  # type: ignore[assignment]
            n = (t_stop - self._t_us) // h_us
            if advance(
                self._x, self._p, self._cmd, self._sched, n, self._t_us, self._base_mode, self._d, self._work
            ):
                raise PlantDivergedError(f"non-finite plant state in ({self._t_us}, {t_stop}] us")
            self._t_us = t_stop
            changed = pending and self._apply_due_events()
            if (fault and self._apply_due_fault()) or changed:
                evaluate(self._x, self._p, self._base_mode, self._d, self._work)

    def _apply_due_fault(self) -> bool:
        """Switch to the faulty propulsion when its time has come (once)."""
        if self._fault_us is None or self._fault_us > self._t_us:
            return False
        self._p = self._p_fault
        self._efficiency = self.params.duct_efficiency
        self._fault_us = None
        return True

    def _apply_due_events(self) -> bool:
        applied = False
        while self._ev_i < len(self._events) and self._events[self._ev_i][0] <= self._t_us:
            ev = self._events[self._ev_i][1]
            if ev.kind == "release":
                self._gripper_closed = False
                self._x[X.MOBJ] = 0.0
            else:
                # the new mass appears at the gripper moving with it: the base velocities are continuous
                self._gripper_closed = True
                self._x[X.MOBJ] = ev.mass_kg
            self._ev_i += 1
            applied = True
        return applied

    def command_gripper(self, close: bool, object_mass_kg: float = 0.0) -> bool:
        """Close the gripper on an object of object_mass_kg, or open it, now (between steps; for a GCS).

        Acts like a scenario grasp/release event at the current time (on the physics grid, since every
        step ends on it). Closing an already closed or opening an open gripper changes nothing. Returns
        True when the state changed. Later scenario events still apply at their times.
        """
        m = float(object_mass_kg)
        if not (math.isfinite(m) and m >= 0.0):
            raise ValueError(f"object_mass_kg must be finite and >= 0, got {object_mass_kg}")
        if bool(close) == self._gripper_closed:
            return False
        self._gripper_closed = bool(close)
        self._x[X.MOBJ] = m if close else 0.0
        evaluate(self._x, self._p, self._base_mode, self._d, self._work)
        return True

    # ---- outputs --------------------------------------------------------------------------------
    def _sample(self) -> int:
        """Sample the sensor groups that are due into self._meas (the others hold); the groups sampled."""
        self._rng.standard_normal(out=self._noise)  # every call draws the same number: a seed fixes the run
        # in place: the groups not due keep their previous sample (sample and hold)
        return sensors.sense(self._x, self._d, self._sig, self._noise, self._meas, self._t_us, self._sensor_due_us,
                       self._sensor_period_us, self._meas)

    def sense(self) -> SensorBundle:
        t = self._t_us
        groups = self._sample()
        s = self._meas.copy()
        s.flags.writeable = False
        # positional: the S layout lists SensorBundle's array fields in its order (test_plant_io checks the fields)
        return SensorBundle(t, *_S_GROUPS(s), self._gripper_closed, groups)

    @property
    def state_vector(self) -> np.ndarray:
        """The state x (plant_layout.X: `x[X.Q.sl]` the joint angles, ...), a read-only copy."""
        x = self._x.copy()
        x.flags.writeable = False
        return x

    def truth(self) -> Truth:
        return self._truth_of(self._x.copy(), self._d.copy())

    def truth_at(self, state: np.ndarray) -> Truth:
        """The truth the plant's dynamics give at the state x (plant_layout.X, e.g. a copy of `state_vector` with
        some slots changed), with this plant's parameters, base mode and command: accelerations, mass properties,
        wrenches. Time, gripper and counters are the plant's now; the plant itself does not change."""
        x = np.array(state, dtype=np.float64)
        if x.shape != (N_X,):
            raise ValueError(f"state must have {N_X} entries (plant_layout.X), got shape {x.shape}")
        d = np.zeros(N_D)
        evaluate(x, self._p, self._base_mode, d, np.zeros(N_WORK))
        return self._truth_of(x, d)

    def _truth_of(self, x: np.ndarray, d: np.ndarray) -> Truth:
        """Truth of the state x and derived quantities d (both owned by the caller; made read-only here)."""
        x.flags.writeable = False
        d.flags.writeable = False
        cmd = self._cmd[_C_ACT].copy()
        cmd.flags.writeable = False
        euler = np.array(quat_to_euler(x[_X_QUAT]))
        euler.flags.writeable = False
        pos, vel, quat, rate, act, actd, jq, jqd, jqdd, jtgt = _TRUTH_X(x)
        acc, wdot, spf, com, fr, mr, mr_o, fr_nog, mr_nog, mr_o_nog, fprop, mprop, fcont, mcont = _TRUTH_D(d)
        return Truth(
            time_us=self._t_us, pos_ned_m=pos, vel_ned_m_s=vel, quat_wxyz=quat, euler_rad=euler, rate_frd_rad_s=rate,
            accel_frd_m_s2=acc, ang_accel_frd_rad_s2=wdot, specific_force_frd_m_s2=spf, actuator_pos=act,
            actuator_rate=actd, actuator_cmd=cmd, joint_pos_rad=jq, joint_rate_rad_s=jqd, joint_accel_rad_s2=jqdd,
            joint_target_rad=jtgt, object_mass_kg=float(x[_X_MOBJ]), gripper_closed=self._gripper_closed,
            mass_kg=float(d[_D_MASS]), com_frd_m=com, inertia_com_kgm2=d[_D_JC].reshape(3, 3),
            inertia_o_kgm2=d[_D_JO].reshape(3, 3), reaction_force_frd_n=fr, reaction_moment_mount_frd_nm=mr,
            reaction_moment_o_frd_nm=mr_o, reaction_force_nog_frd_n=fr_nog, reaction_moment_mount_nog_frd_nm=mr_nog,
            reaction_moment_o_nog_frd_nm=mr_o_nog, prop_force_frd_n=fprop, prop_moment_frd_nm=mprop,
            contact_force_frd_n=fcont, contact_moment_frd_nm=mcont, contact_points_active=int(d[_D_NCONT]),
            cmd_nonfinite_count=self._guard.nonfinite, cmd_clamped_count=self._guard.clamped,
        )

    def sense_wire(self) -> WireSensors:
        """sense() as plain Python floats in lists (WireSensors): the same sample, the same rng draws, for the
        bridge's encoder without the numpy views it would convert back at once."""
        groups = self._sample()
        g, a, p, v, q, tilt, speed, jp, jr = _S_GROUPS(self._meas.tolist())
        return _fill(WireSensors(), time_us=self._t_us, gyro_frd_rad_s=g, accel_frd_m_s2=a, pos_ned_m=p, vel_ned_m_s=v,
                     quat_wxyz=q, duct_tilt_rad=tilt, prop_speed_rad_s=speed, joint_pos_rad=jp, joint_rate_rad_s=jr,
                     gripper_closed=self._gripper_closed, updated=groups)

    def truth_floats(self) -> TruthFloats:
        """truth() as plain Python floats (seam.TruthFloats; the same values): what NAVIG8_TRUTH carries and /truth
        logs, without the numpy views the encoder and the log would convert back at once."""
        return _truth_floats(self._t_us, self._x.tolist(), self._d.tolist(), self._guard.nonfinite,
                             self._guard.clamped)

    def truth_state(self) -> TruthState:
        """The truth as raw bytes of the state and its derived quantities, cheap to hand to another process (the
        log writer): truth_floats_of_state gives back exactly truth_floats()."""
        return self._t_us, self._x.tobytes(), self._d.tobytes(), self._guard.nonfinite, self._guard.clamped

    def trim_command(self) -> ActuatorCommand:
        """Level hover trim for the current arm pose and object (vehicle.hover_trim) of the ducts as they are now (a
        duct fault once it has struck), clamped to limits."""
        act = np.clip(
            trim_actuators(self.vehicle, self._x[X.Q.sl], float(self._x[X.MOBJ]), self._efficiency),
            self._act_lo,
            self._act_hi,
        )
        return ActuatorCommand((float(act[0]), float(act[1])), (float(act[2]), float(act[3]), float(act[4])))
