"""The robustness envelope's draws: one randomised, seeded flight per sample, for a campaign's `generator: envelope`.

    scenario, world, fc_params, factors = draw(sample_index, rng_seed, spec)

`draw` is a pure function of its arguments: sample k of seed s is drawn from Generator(SeedSequence([s, k])), so
a draw is reproducible alone, and adding samples or reordering rows never changes the others. A draw is a
complete run description:

- `scenario`: a scenario document (the format of params/scenarios/*.yaml) starting armed in hover with the
  actuators at trim: the flight's shape (the arm's motion as ramped `steps`, the grasp and release events, the
  pitch, yaw and position setpoint steps) and its duration;
- `world`: world overrides of sim_bridge.world (the plant's servo speed, actuator bandwidth, sensor noise; the
  vehicle's tail thrust);
- `fc_params`: flight-controller parameters (the FC's own model of the arm's servo, with its drawn error);
- `factors`: the drawn values as table columns, and the plant/sensor seed of the run (`seed`).

The timeline of a flight (times after the arm has *arrived* come from the plant's own servo law run over the
drawn schedule, `servo_track`, so a grasp "at the stretched pose" happens with the arm at that pose, however
slow the drawn servo):

    0 .. t_a          hover, arm down (q = 0)
    t_a               grasp pattern: the arm moves (ramp_s drawn) to the grasp pose (stretched or random)
    t_g               grasp (the arm at rest at the pose for a drawn margin), object of the drawn mass
    t_g+ .. t_rc      the motion shape: square wave (Eq. 26-like), slow sweep, steps, or random targets
    t_rc              release pattern: the arm moves to the release pose; the latest t_rc that still lets the
                      servo arrive before the release time (the shape is cut there)
    t_r               release, D - post; when drawn "while pitched", the pitch step holds over t_r
    D                 end (20-25 s)

The object patterns: `grasp` (the gripper starts open, grasps, holds to the end), `release` (the object is held
from the start and released), `grasp_release` (both). Why these ranges: docs/campaigns.md, "The robustness
envelope".
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, fields, replace
from typing import Any

import numpy as np

from navig8_fc.core.jit import njit_cached
from navig8_fc.flight.script import arm_segments, target_at
from sim_bridge import joint_servo
from sim_bridge.joint_servo import schedule_target, servo_accel

Vec3 = tuple[float, float, float]
SHAPES = ("square", "sweep", "steps", "random")
PATTERNS = ("grasp", "release", "grasp_release")
ARRIVE_TOL_RAD = math.radians(0.05)  # the servo's pose counts as arrived within this, on every joint
SERVO_H_S = 1e-3  # the servo law's period in the timeline's simulation (params/plant.yaml servo_rate_hz)


@dataclass(frozen=True)
class EnvelopeSpec:
    """The ranges of the draws (a campaign's `envelope:` key overrides any of them) and the nominal values they are
    relative to (from the packaged vehicle, plant and parameter files: `EnvelopeSpec.from_dict`).

    Ranges are [lo, hi]; `*_log` ranges are drawn log-uniformly (scales and rates: as many draws below the nominal
    as above it), the others uniformly."""

    duration_s: tuple[float, float] = (20.0, 25.0)
    hover_z_ned_m: float = -3.0  # 3 m up: a 2 m downward position step still ends 1 m above the ground
    object_mass_kg: tuple[float, float] = (0.0, 2.5)
    patterns: tuple[str, ...] = PATTERNS
    stretched_pose_deg: Vec3 = (80.0, 10.0, 10.0)
    stretched_fraction: float = 0.5  # share of grasp and of release poses that are the stretched arm
    release_pitched_fraction: float = 0.5  # share of releases made with the pitch setpoint held over them
    arm_speed_rad_s_log: tuple[float, float] = (0.3, 4.0)  # the plant's servo rate limit
    servo_model_error_log: tuple[float, float] = (0.8, 1.25)  # the FC's servo model: nominal x this (a x this^2)
    shapes: tuple[str, ...] = SHAPES
    square_amplitude_deg: tuple[float, float] = (5.0, 30.0)
    square_half_period_s: tuple[float, float] = (0.5, 4.0)
    sweep_leg_s: tuple[float, float] = (3.0, 8.0)  # one linear leg of a sweep to a random pose
    step_amplitude_deg: tuple[float, float] = (-45.0, 45.0)  # steps: per joint, around q = 0
    random_ramp_s: tuple[float, float] = (0.0, 2.0)  # random targets: each reached by a ramp of this length
    hold_s: tuple[float, float] = (1.0, 4.0)  # steps and random targets: time at each pose
    arrive_margin_s: tuple[float, float] = (0.3, 1.0)  # at rest at the pose this long before a grasp/release
    pitch_deg: tuple[float, float] = (0.0, 45.0)
    pitch_hold_s: tuple[float, float] = (3.0, 8.0)
    yaw_step_deg: tuple[float, float] = (-90.0, 90.0)
    pos_step_m: tuple[float, float] = (0.0, 2.0)
    actuator_bandwidth_scale: tuple[float, float] = (0.6, 1.4)
    sensor_noise_scale_log: tuple[float, float] = (0.5, 2.0)
    tail_max_thrust_n: tuple[float, float] = (60.0, 200.0)
    post_release_s: tuple[float, float] = (2.5, 5.0)  # flown after the release
    # nominal values (from the packaged files; the draws scale them)
    joint_limit_rad: float = 1.75
    plant_servo_v_max_rad_s: float = 4.0
    plant_servo_a_max_rad_s2: float = 42.0
    fc_servo_v_max_rad_s: float = 4.0  # ARM_SERVO_VMAX's default
    fc_servo_a_max_rad_s2: float = 42.0  # ARM_SERVO_AMAX's default

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, tuple) and len(v) == 2 and all(isinstance(x, float) for x in v) and not v[0] <= v[1]:
                raise ValueError(f"envelope {f.name}: [lo, hi] with lo <= hi, got {list(v)}")
        for name in ("arm_speed_rad_s_log", "servo_model_error_log", "sensor_noise_scale_log"):
            if getattr(self, name)[0] <= 0.0:
                raise ValueError(f"envelope {name}: a log-uniform range must be > 0")
        for name in ("square_half_period_s", "sweep_leg_s", "hold_s"):  # the arm's motion advances by these steps
            if getattr(self, name)[0] <= 0.0:
                raise ValueError(f"envelope {name}: the range must be > 0 (a zero step never ends the motion)")
        if set(self.shapes) - set(SHAPES) or not self.shapes:
            raise ValueError(f"envelope shapes: a non-empty subset of {SHAPES}, got {list(self.shapes)}")
        if set(self.patterns) - set(PATTERNS) or not self.patterns:
            raise ValueError(f"envelope patterns: a non-empty subset of {PATTERNS}, got {list(self.patterns)}")
        lim = math.degrees(self.joint_limit_rad)
        if max(abs(x) for x in (*self.stretched_pose_deg, *self.step_amplitude_deg)) > lim \
                or self.square_amplitude_deg[1] > lim:
            raise ValueError(f"envelope poses must lie within the joint limits (+-{lim:.1f} deg)")
        if self.duration_s[0] < 12.0:
            raise ValueError("envelope duration_s: at least 12 s (grasp, motion and release need the time)")

    @staticmethod
    def from_dict(d: Mapping[str, Any] | None = None, nominal: Mapping[str, float] | None = None) -> EnvelopeSpec:
        """A spec from a campaign's `envelope:` mapping (keys as the fields; unknown keys refuse), over the
        nominal values of the packaged files (`nominal_values()`) unless `nominal` gives them."""
        d = dict(d or {})
        known = {f.name: f for f in fields(EnvelopeSpec)}
        unknown = set(d) - set(known)
        if unknown:
            raise ValueError(f"envelope: unknown keys {sorted(unknown)} (known: {sorted(known)})")
        kw: dict[str, Any] = dict(nominal_values() if nominal is None else nominal)
        for k, v in d.items():
            kw[k] = tuple(str(x) for x in v) if k in ("shapes", "patterns") else (
                tuple(float(x) for x in v) if isinstance(v, (list, tuple)) else float(v))
        return replace(EnvelopeSpec(), **kw)

    def as_dict(self) -> dict[str, Any]:
        """The spec as plain data (for a run id's content and the report)."""
        return {f.name: (list(getattr(self, f.name)) if isinstance(getattr(self, f.name), tuple)
                         else getattr(self, f.name)) for f in fields(self)}


def nominal_values() -> dict[str, float]:
    """The values the draws are relative to: the joint limit (params/vehicle.yaml), the plant's servo
    (params/plant.yaml) and the FC's servo model defaults (ARM_SERVO_VMAX/AMAX, params/fc_params.yaml)."""
    from navig8_fc.core.vehicle import VehicleConfig
    from navig8_fc.params.registry import ParamRegistry
    from sim_bridge.params import PlantParams

    plant, reg = PlantParams.load(), ParamRegistry.from_defaults()
    return {"joint_limit_rad": VehicleConfig.load().joint_limit_rad,
            "plant_servo_v_max_rad_s": plant.joint_v_max_rad_s, "plant_servo_a_max_rad_s2": plant.joint_a_max_rad_s2,
            "fc_servo_v_max_rad_s": float(reg["ARM_SERVO_VMAX"]), "fc_servo_a_max_rad_s2": float(reg["ARM_SERVO_AMAX"])}


# ---------------------------------------------------------------------------------------------
# The plant's servo over a schedule (to time grasps and releases after the arm has arrived)
# ---------------------------------------------------------------------------------------------


@njit_cached(joint_servo)  # it calls the plant's servo kernels: a change there recompiles it
def _servo_track(sched: np.ndarray, q0: np.ndarray, qd0: np.ndarray, t0_us: int, h_us: int, n: int, v_max: float,
                 a_max: float, every: int) -> np.ndarray:
    """Joint angles every `every` servo periods from t0_us, the plant's servo law (sim_bridge.joint_servo.servo_update:
    the target of the schedule, the rate/acceleration-limited law, exact constant-acceleration steps, the snap at
    rest) from the state (q0, qd0). Rows: t_us, q1, q2, q3."""
    h = h_us * 1e-6
    q = q0.copy()
    qd = qd0.copy()
    out = np.empty((n // every + 1, 4))
    for k in range(n + 1):
        t_us = t0_us + k * h_us
        if k % every == 0:
            r = k // every
            out[r, 0] = t_us
            out[r, 1] = q[0]
            out[r, 2] = q[1]
            out[r, 3] = q[2]
        if k == n:
            break
        for j in range(3):
            tgt = schedule_target(sched, float(t_us), j)
            if abs(tgt - q[j]) <= 1e-12 and abs(qd[j]) <= 1e-9:
                q[j] = tgt
                qd[j] = 0.0
            else:
                a = servo_accel(tgt - q[j], qd[j], h, a_max, v_max)
                q[j] += qd[j] * h + 0.5 * a * h * h
                qd[j] += a * h
    return out


def schedule_rows(steps: Sequence[Mapping[str, Any]], q0_rad: Vec3, duration_s: float) -> np.ndarray:
    """The plant's arm schedule (rows [t0_us, t1_us, qa, qb]) of an `arm: {kind: steps}` list, through the one
    parser of the `arm` key (navig8_fc.flight.script.arm_segments)."""
    segs = arm_segments("steps", {"steps": list(steps)}, q0_rad, duration_s)
    return np.array([[round(s.t0_s * 1e6), round(s.t1_s * 1e6), *s.q_start_rad, *s.q_end_rad] for s in segs],
                    dtype=np.float64)


def servo_track(steps: Sequence[Mapping[str, Any]], duration_s: float, v_max: float, a_max: float,
                every: int = 10) -> np.ndarray:
    """The plant's joint angles (rad) over [0, duration_s] for an arm `steps` list starting at rest at q = 0, sampled
    every `every` ms: rows t_s, q1, q2, q3."""
    sched = schedule_rows(steps, (0.0, 0.0, 0.0), duration_s)
    n = int(round(duration_s / SERVO_H_S))
    out = _servo_track(sched, np.zeros(3), np.zeros(3), 0, round(SERVO_H_S * 1e6), n, v_max, a_max, every)
    out[:, 0] *= 1e-6
    return out


def arrival_s(track: np.ndarray, pose_rad: np.ndarray, t_from_s: float) -> float:
    """The first time >= t_from_s from which the track stays within ARRIVE_TOL_RAD of pose on every joint (inf if
    it never settles there)."""
    far = np.any(np.abs(track[:, 1:] - pose_rad) > ARRIVE_TOL_RAD, axis=1) | (track[:, 0] < t_from_s - 1e-9)
    if far[-1]:
        return math.inf
    idx = np.nonzero(far)[0]
    k = 0 if len(idx) == 0 else int(idx[-1]) + 1
    return float(track[k, 0])


# ---------------------------------------------------------------------------------------------
# The draw
# ---------------------------------------------------------------------------------------------


def _r(x: float, nd: int) -> float:
    """Rounded to nd decimals as a plain float: the files stay readable and the rows carry what runs."""
    return float(round(float(x), nd))


def _u(rng: np.random.Generator, lohi: tuple[float, float]) -> float:
    return float(rng.uniform(lohi[0], lohi[1]))


def _logu(rng: np.random.Generator, lohi: tuple[float, float]) -> float:
    return float(math.exp(rng.uniform(math.log(lohi[0]), math.log(lohi[1]))))


def _pose(q_deg: Sequence[float], lim_deg: float) -> list[float]:
    """A pose rounded to 0.01 deg and kept inside the joint limit (the rounding must not step over it)."""
    inner = math.floor(lim_deg * 100.0) / 100.0
    return [min(max(_r(x, 2), -inner), inner) for x in q_deg]


def _random_pose(rng: np.random.Generator, lim_deg: float) -> list[float]:
    return _pose(rng.uniform(-lim_deg, lim_deg, 3), lim_deg)


def _shape_steps(rng: np.random.Generator, shape: str, spec: EnvelopeSpec, q_from_deg: Sequence[float], t0: float,
                 t1: float) -> tuple[list[dict[str, Any]], dict[str, float]]:
    """The motion shape's arm steps on [t0, t1) from the target q_from_deg, and its parameters (table columns)."""
    lim = math.degrees(spec.joint_limit_rad)
    steps: list[dict[str, Any]] = []
    par: dict[str, float] = {"shape_amplitude_deg": math.nan, "shape_period_s": math.nan}
    if shape == "square":
        # Eq. 26's square wave (all three joints +-A, half-period T, the first pose reached by a ramp as the paper's
        # "gradually"), around the pose the shape starts from (moved inside the limits), so a stretched grasp pose
        # is waved about, and a shape starting from q = 0 is Eq. 26 itself
        a = _r(_u(rng, spec.square_amplitude_deg), 2)
        half = _r(_u(rng, spec.square_half_period_s), 3)
        centre = [min(max(float(q), -lim + a), lim - a) for q in q_from_deg]
        ramp = _r(rng.uniform(0.0, half), 3)
        sign, t = 1.0, t0
        while t < t1 - 1e-9:
            steps.append({"t_s": _r(t, 3), "q_deg": _pose([c + sign * a for c in centre], lim),
                          **({"ramp_s": ramp} if t == t0 and ramp > 0.0 else {})})
            sign, t = -sign, t + half
        par = {"shape_amplitude_deg": a, "shape_period_s": half}
    elif shape == "sweep":
        # slow sweeps: linear legs of several seconds to random poses within the limits
        t, legs = t0, []
        while t < t1 - 1e-9:
            leg = _r(min(_u(rng, spec.sweep_leg_s), t1 - t), 3)
            steps.append({"t_s": _r(t, 3), "q_deg": _random_pose(rng, lim), "ramp_s": max(leg, 0.001)})
            legs.append(leg)
            t += leg
        par = {"shape_amplitude_deg": math.nan, "shape_period_s": _r(float(np.mean(legs)), 3) if legs else math.nan}
    else:
        # steps: per-joint steps around q = 0 (the paper's pose changes, generalised); random: targets anywhere
        # within the joint limits, each reached by a drawn ramp
        t = t0
        while t < t1 - 1e-9:
            if shape == "steps":
                steps.append({"t_s": _r(t, 3), "q_deg": _pose(rng.uniform(*spec.step_amplitude_deg, 3), lim)})
            else:
                ramp = _r(_u(rng, spec.random_ramp_s), 3)
                steps.append({"t_s": _r(t, 3), "q_deg": _random_pose(rng, lim),
                              **({"ramp_s": ramp} if ramp > 0.0 else {})})
            t += _r(_u(rng, spec.hold_s), 3)
        par = {"shape_amplitude_deg": math.nan, "shape_period_s": math.nan}
    return steps, par


def _target_deg_at(steps: Sequence[Mapping[str, Any]], t_s: float) -> list[float]:
    """The commanded target (deg) of an arm steps list at t_s (from q = 0)."""
    segs = arm_segments("steps", {"steps": list(steps)}, (0.0, 0.0, 0.0), t_s + 1.0)
    i = max(k for k, s in enumerate(segs) if s.t0_s <= t_s)
    return [math.degrees(x) for x in target_at(segs[i], t_s)]


@dataclass(frozen=True)
class _Factors:
    """The draw's scalar factors, in the order the generator gives them (draw's first step)."""

    lim_deg: float
    duration: float
    seed: int
    mass: float
    pattern: str
    shape: str
    speed_scale: float
    v_max: float
    a_max: float
    model_err: float
    bandwidth: float
    noise: float
    tail: float
    grasping: bool
    releasing: bool
    grasp_stretched: bool
    release_stretched: bool
    grasp_pose: list[float]
    release_pose: list[float]
    release_pitched: bool
    margins: list[float]
    post: float


def _draw_factors(rng: np.random.Generator, spec: EnvelopeSpec) -> _Factors:
    lim = math.degrees(spec.joint_limit_rad)
    duration = _r(_u(rng, spec.duration_s), 3)
    seed = int(rng.integers(1, 2**31 - 1))
    mass = _r(_u(rng, spec.object_mass_kg), 3)
    pattern = spec.patterns[int(rng.integers(len(spec.patterns)))]
    shape = spec.shapes[int(rng.integers(len(spec.shapes)))]
    v_max = _logu(rng, spec.arm_speed_rad_s_log)
    speed_scale = _r(v_max / spec.plant_servo_v_max_rad_s, 5)
    v_max = speed_scale * spec.plant_servo_v_max_rad_s  # what the world override gives the plant
    a_max = speed_scale**2 * spec.plant_servo_a_max_rad_s2
    model_err = _r(_logu(rng, spec.servo_model_error_log), 4)
    bandwidth = _r(_u(rng, spec.actuator_bandwidth_scale), 4)
    noise = _r(_logu(rng, spec.sensor_noise_scale_log), 4)
    tail = _r(_u(rng, spec.tail_max_thrust_n), 2)
    grasping, releasing = pattern in ("grasp", "grasp_release"), pattern in ("release", "grasp_release")
    stretched = [float(x) for x in spec.stretched_pose_deg]
    # the poses and flags are drawn whether used or not, so one pattern's draw does not shift the others' numbers
    grasp_stretched, release_stretched = (bool(rng.random() < spec.stretched_fraction) for _ in range(2))
    grasp_pose = stretched if grasp_stretched else _random_pose(rng, lim)
    release_pose = stretched if release_stretched else _random_pose(rng, lim)
    release_pitched = releasing and bool(rng.random() < spec.release_pitched_fraction)
    margins = [_r(_u(rng, spec.arrive_margin_s), 3) for _ in range(2)]
    post = _r(_u(rng, spec.post_release_s), 3)
    return _Factors(lim, duration, seed, mass, pattern, shape, speed_scale, v_max, a_max, model_err, bandwidth, noise,
                    tail, grasping, releasing, grasp_stretched, release_stretched, grasp_pose, release_pose,
                    release_pitched, margins, post)


def _release_schedule(f: _Factors, steps: list[dict[str, Any]], shape_steps: list[dict[str, Any]], t: float,
                      release_ramp: float) -> tuple[list[dict[str, Any]], float, str]:
    """The arm's steps up to the release: the latest command time for the release pose from which the servo is at
    rest there `margin` before the release (the shape cut at ever earlier times, 0.25 s apart, until the move fits),
    or a release where the arm is when even without a shape it cannot get there. (steps, release time, kind)."""
    t_release = _r(f.duration - f.post, 3)
    t_cmd = t_release - f.margins[1] - release_ramp
    while t_cmd >= t - 1e-9:
        cut = [s for s in shape_steps if s["t_s"] < t_cmd - 1e-9]
        trial = [*steps, *cut, {"t_s": _r(t_cmd, 3), "q_deg": _pose(f.release_pose, f.lim_deg), "ramp_s": release_ramp}]
        arrive = arrival_s(servo_track(trial, f.duration, f.v_max, f.a_max), np.radians(f.release_pose), t_cmd)
        if arrive + f.margins[1] <= t_release + 1e-9:
            return trial, t_release, "stretched" if f.release_stretched else "random"
        t_cmd -= 0.25
    return steps + [s for s in shape_steps if s["t_s"] < t_release - 1e-9], t_release, "in_place"


def _arm_schedule(rng: np.random.Generator, spec: EnvelopeSpec, f: _Factors
                  ) -> tuple[list[dict[str, Any]], dict[str, float], float, float, str]:
    """The arm's steps (grasp pose, the shape, the release pose), the shape's parameters, the grasp and release
    times and the release's kind."""
    steps: list[dict[str, Any]] = []
    t = _r(rng.uniform(0.5, 1.5), 3)
    t_grasp = math.nan
    if f.grasping:
        steps.append({"t_s": t, "q_deg": _pose(f.grasp_pose, f.lim_deg),
                      "ramp_s": _r(rng.uniform(0.0, 1.5), 3) or 0.001})
        track = servo_track(steps, f.duration, f.v_max, f.a_max)
        t_grasp = _r(arrival_s(track, np.radians(f.grasp_pose), t) + f.margins[0], 3)
        t = _r(t_grasp + rng.uniform(0.3, 1.0), 3)
    q_from = _target_deg_at(steps, t) if steps else [0.0, 0.0, 0.0]
    t_end_shape = f.duration - f.post if f.releasing else f.duration
    shape_steps, shape_par = _shape_steps(rng, f.shape, spec, q_from, t, max(t, t_end_shape))
    t_release, release_kind = math.nan, "none"
    release_ramp = _r(rng.uniform(0.0, 1.5), 3) or 0.001
    if f.releasing:
        steps, t_release, release_kind = _release_schedule(f, steps, shape_steps, t, release_ramp)
    else:
        steps = steps + shape_steps
    if not steps:
        steps = [{"t_s": 0.0, "q_deg": [0.0, 0.0, 0.0]}]
    return steps, shape_par, t_grasp, t_release, release_kind


def _setpoint_steps(rng: np.random.Generator, spec: EnvelopeSpec, f: _Factors, t_release: float
                    ) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """The setpoint steps (a pitch held and levelled, a yaw step, a position step) and their factors."""
    duration = f.duration
    pitch = _r(_u(rng, spec.pitch_deg), 2)
    yaw_step = _r(_u(rng, spec.yaw_step_deg), 2)
    step_m = _u(rng, spec.pos_step_m)
    direction = rng.normal(size=3)
    direction /= max(float(np.linalg.norm(direction)), 1e-12)
    dpos = [_r(step_m * x, 3) for x in direction]
    t_yaw = _r(rng.uniform(2.0, duration - 4.0), 3)
    t_pos = _r(rng.uniform(2.0, duration - 5.0), 3)
    if f.release_pitched:
        t_pitch = _r(max(1.0, t_release - rng.uniform(2.0, 5.0)), 3)
        t_level = _r(t_release + rng.uniform(1.0, 2.0), 3)
    else:
        t_pitch = _r(rng.uniform(2.0, duration - 8.0), 3)
        t_level = _r(t_pitch + _u(rng, spec.pitch_hold_s), 3)
    z0 = float(spec.hover_z_ned_m)
    sp_steps: list[dict[str, Any]] = [
        {"t_s": t_pitch, "pitch_deg": pitch},
        {"t_s": t_yaw, "yaw_deg": yaw_step},
        {"t_s": t_pos, "x_ned_m": dpos[0], "y_ned_m": dpos[1], "z_ned_m": _r(z0 + dpos[2], 3)},
    ]
    if t_level < duration:
        sp_steps.append({"t_s": t_level, "pitch_deg": 0.0})
    sp_steps.sort(key=lambda s: s["t_s"])
    pitched_at_release = f.releasing and t_pitch <= t_release < t_level
    factors = {"release_pitch_deg": pitch if pitched_at_release else (0.0 if f.releasing else math.nan),
               "pitch_deg": pitch, "pitch_t_s": t_pitch, "yaw_step_deg": yaw_step, "yaw_t_s": t_yaw,
               "pos_step_m": _r(math.sqrt(sum(x * x for x in dpos)), 3), "pos_t_s": t_pos}
    return sp_steps, factors


def draw(sample_index: int, rng_seed: int, spec: EnvelopeSpec
         ) -> tuple[dict[str, Any], dict[str, float], dict[str, float], dict[str, Any]]:
    """Sample `sample_index` of the envelope (module docstring): (scenario document, world overrides, FC
    parameters, factor values). Pure: the same arguments give the same draw, bit for bit."""
    rng = np.random.default_rng(np.random.SeedSequence([int(rng_seed), int(sample_index)]))
    f = _draw_factors(rng, spec)
    steps, shape_par, t_grasp, t_release, release_kind = _arm_schedule(rng, spec, f)
    track = servo_track(steps, f.duration, f.v_max, f.a_max, every=1)

    def pose_at(t_s: float) -> list[float]:
        if not math.isfinite(t_s):
            return [math.nan] * 3
        k = int(np.searchsorted(track[:, 0], t_s - 1e-9))
        return [_r(math.degrees(x), 2) for x in track[min(k, len(track) - 1), 1:]]

    events: list[dict[str, Any]] = []
    if f.grasping:
        events.append({"t_s": t_grasp, "kind": "grasp", "mass_kg": f.mass})
    if f.releasing:
        events.append({"t_s": t_release, "kind": "release"})
    sp_steps, sp_factors = _setpoint_steps(rng, spec, f, t_release)
    z0 = float(spec.hover_z_ned_m)
    pattern, mass = f.pattern, f.mass
    scenario: dict[str, Any] = {
        "name": f"envelope_{int(rng_seed)}_{int(sample_index):04d}",
        "description": f"Robustness envelope draw {sample_index} of seed {rng_seed} (tools/envelope.py): "
                       f"{pattern}, {f.shape} arm motion, {mass:g} kg object.",
        "duration_s": f.duration,
        "armed": True,
        "initial": {"pos_ned_m": [0.0, 0.0, z0], "vel_ned_m_s": [0.0, 0.0, 0.0], "euler_deg": [0.0, 0.0, 0.0],
                    "rate_frd_rad_s": [0.0, 0.0, 0.0], "joint_pos_deg": [0.0, 0.0, 0.0], "actuators": "trim",
                    "on_ground": False},
        "object": {"gripper_closed": pattern == "release", "mass_kg": mass if pattern == "release" else 0.0},
        "events": events,
        "arm": {"kind": "steps", "steps": steps},
        "setpoints": {"initial": {"pos_ned_m": [0.0, 0.0, z0], "pitch_deg": 0.0, "yaw_deg": 0.0},
                      "steps": sp_steps},
    }
    world = {"arm_servo_speed_scale": f.speed_scale, "actuator_bandwidth_scale": f.bandwidth,
             "sensor_noise_scale": f.noise, "tail_max_thrust_n": f.tail}
    fc_params = {"ARM_SERVO_VMAX": _r(spec.fc_servo_v_max_rad_s * f.model_err, 5),
                 "ARM_SERVO_AMAX": _r(spec.fc_servo_a_max_rad_s2 * f.model_err**2, 5)}
    g_pose, r_pose = pose_at(t_grasp), pose_at(t_release)
    factors: dict[str, Any] = {
        "seed": f.seed, "duration_s": f.duration, "pattern": pattern, "object_mass_kg": mass,
        "grasp_t_s": t_grasp, "release_t_s": t_release,
        "grasp_pose": ("stretched" if f.grasp_stretched else "random") if f.grasping else "none",
        "release_pose": release_kind,
        **{f"grasp_q{j + 1}_deg": g_pose[j] for j in range(3)},
        **{f"release_q{j + 1}_deg": r_pose[j] for j in range(3)},
        "release_pitch_deg": sp_factors.pop("release_pitch_deg"),
        "arm_shape": f.shape, **shape_par,
        "arm_speed_rad_s": _r(f.v_max, 4), "arm_accel_rad_s2": _r(f.a_max, 4),
        "servo_model_error": f.model_err,
        # the FC's servo model over the plant's servo: the drawn error times the drawn plant's departure from nominal
        "servo_model_ratio": _r(fc_params["ARM_SERVO_VMAX"] / f.v_max, 4),
        **sp_factors,
        "tail_max_thrust_n": f.tail, "actuator_bandwidth_scale": f.bandwidth, "sensor_noise_scale": f.noise,
    }
    return scenario, world, fc_params, factors


__all__ = ["EnvelopeSpec", "draw", "nominal_values", "servo_track", "schedule_rows", "SHAPES", "PATTERNS"]
