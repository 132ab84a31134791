"""INDI inner loop (paper Sec. 2.2 and 3, Eq. 5-6) with saturation handling.

Each control step:
- angular acceleration from differentiating the low-passed gyro; body specific force x, z low-passed
  with the same filter (tau = INDI_LPF_TAU): Acc_f = [Pdot, Qdot, Rdot, a_x, a_z] filtered;
- U0 from the measured duct angles and propeller speeds, passed through the same low-pass so the
  increment is unbiased by the filter lag (notes §4, Paparazzi's synchronisation);
- Delta Acc = v - Acc_f; Delta U = G_C,UAM^-1 G_hat_I Delta Acc (Eq. 5); U = U0 + Delta U (Eq. 6);
- U -> (alpha1, alpha3, w1, w2, w3) (Sec. 3), respecting the actuator limits.

Saturation: when U would leave the feasible set, the increment is scaled back axis group by axis
group, lowest priority first: (1) forward force a_x, (2) yaw Rdot, (3) roll, pitch and vertical
force, which are kept as long as possible (bisection on a scale factor per group). The result is
then clipped into the limits, and a non-finite U falls back to U0 (never NaN to the actuators).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from navig8_fc.core import _kernels as _k
from navig8_fc.core.filters import BackwardDifference, LowPass1, lpf_alpha
from navig8_fc.core.vehicle import VehicleConfig, u_to_actuators

# Axis groups of Delta Acc = [Pdot, Qdot, Rdot, a_x, a_z], scaled back in this order on saturation.
SATURATION_ORDER: tuple[tuple[int, ...], ...] = ((3,), (2,), (0, 1, 4))


@dataclass(frozen=True)
class ActuatorLimits:
    tilt_min_rad: float
    tilt_max_rad: float
    duct_speed_max: float
    tail_speed_max: float

    @staticmethod
    def from_vehicle(cfg: VehicleConfig) -> ActuatorLimits:
        return ActuatorLimits(cfg.tilt_min_rad, cfg.tilt_max_rad, cfg.duct_speed_max, cfg.tail_speed_max)


@dataclass(frozen=True)
class IndiConfig:
    dt_s: float
    lpf_tau_s: float
    limits: ActuatorLimits


@dataclass(frozen=True)
class IndiInputs:
    gyro_frd: Sequence[float]  # rad/s, measured
    specific_force_frd: Sequence[float]  # m/s^2, accelerometer (specific force at O)
    tilt_rad: Sequence[float]  # measured alpha1, alpha3
    speed_rad_s: Sequence[float]  # measured w1, w2 (signed), w3
    accel_cmd: Sequence[float]  # v = [Pdot, Qdot, Rdot, a_x, a_z] commanded
    gc: np.ndarray  # G_C,UAM (5x5)
    gi_hat: np.ndarray  # G_hat_I (5x5)
    gc_inv: np.ndarray | None = None  # G_C,UAM^-1 if the caller already has it (saves a solve per tick)


@dataclass(frozen=True)
class IndiOutput:
    tilt_cmd_rad: tuple[float, float]
    speed_cmd_rad_s: tuple[float, float, float]  # w1, w2 (signed), w3
    u_cmd: tuple[float, ...]


@dataclass(frozen=True)
class IndiStatus:
    acc_filtered: tuple[float, ...]  # [Pdot, Qdot, Rdot, a_x, a_z] after the LPF
    u0_filtered: tuple[float, ...]
    delta_acc: tuple[float, ...]
    delta_u: tuple[float, ...]  # increment actually applied (after saturation handling)
    saturation_scale: tuple[float, float, float]  # per group in SATURATION_ORDER, 1 = untouched
    saturated: bool
    fallback_to_u0: bool


def actuators_to_u_list(alpha1: float, alpha3: float, w1: float, w2: float, w3: float) -> list[float]:
    """vehicle.actuators_to_u as a list of floats (the same expressions; no array for 5 numbers)."""
    return [
        math.cos(alpha1) * w1 * w1,
        math.sin(alpha1) * w1 * w1,
        math.cos(alpha3) * w3 * w3,
        math.sin(alpha3) * w3 * w3,
        math.copysign(w2 * w2, w2),
    ]


class IndiControllerReference:
    """Incremental nonlinear dynamic inversion on [Pdot, Qdot, Rdot, a_x, a_z] (plain Python / numpy).

    The reference for the compiled `IndiController` (tests compare the two); not on the hot path.
    """

    def __init__(self, cfg: IndiConfig) -> None:
        self.cfg = cfg
        self._gyro_lpf = LowPass1(cfg.lpf_tau_s, cfg.dt_s, 3)
        self._diff = BackwardDifference(cfg.dt_s, 3)
        self._acc_lpf = LowPass1(cfg.lpf_tau_s, cfg.dt_s, 2)
        self._u0_lpf = LowPass1(cfg.lpf_tau_s, cfg.dt_s, 5)
        lim = cfg.limits
        self._w_duct_sq_max = lim.duct_speed_max**2
        self._w_tail_sq_max = lim.tail_speed_max**2

    def reset(self) -> None:
        for f in (self._gyro_lpf, self._diff, self._acc_lpf, self._u0_lpf):
            f.reset()

    def measure(self, inp: IndiInputs) -> tuple[list[float], list[float]]:
        """Filtered acceleration feedback and filtered U0 (also used while disarmed, to stay warm)."""
        w_f = self._gyro_lpf.step(inp.gyro_frd)
        wdot = self._diff.step(w_f)
        f_xz = self._acc_lpf.step((inp.specific_force_frd[0], inp.specific_force_frd[2]))
        a1, a3 = inp.tilt_rad
        w1, w2, w3 = inp.speed_rad_s
        u0 = self._u0_lpf.step(actuators_to_u_list(a1, a3, w1, w2, w3))
        return [wdot[0], wdot[1], wdot[2], f_xz[0], f_xz[1]], u0

    def step(self, inp: IndiInputs) -> tuple[IndiOutput, IndiStatus]:
        acc_f, u0 = self.measure(inp)
        d_acc_l = [inp.accel_cmd[i] - acc_f[i] for i in range(5)]
        # Eq. 5: Delta U = G_C^-1 G_hat_I Delta Acc (np.dot: the same BLAS products as @, less overhead)
        m = np.dot(inp.gc_inv, inp.gi_hat) if inp.gc_inv is not None else np.linalg.solve(inp.gc, inp.gi_hat)
        u0_arr = np.array(u0)
        scales = [1.0, 1.0, 1.0]
        fallback = False
        du = np.dot(m, d_acc_l)
        u = u0_arr + du
        ul = u.tolist()
        if not self._feasible(ul):
            # Keep the high-priority groups; scale the low ones back first, to the largest feasible s.
            d_acc = np.array(d_acc_l)
            contrib = m * d_acc  # column j = M[:, j] * d_acc[j]: each axis' contribution
            rest = du.copy()
            for g, cols in enumerate(SATURATION_ORDER):
                part = contrib[:, list(cols)].sum(axis=1)
                base = rest - part
                if self._feasible(u0_arr + base + part):
                    break
                s = self._max_scale(u0_arr + base, part)
                scales[g] = s
                rest = base + s * part
                if self._feasible(u0_arr + rest):
                    break
            du = rest
            u = u0_arr + du
            ul = u.tolist()
        if not all(math.isfinite(v) for v in ul):
            u, du, fallback = u0_arr.copy(), np.zeros(5), True
            ul = u.tolist()
        a1, a3, w1, w2, w3 = u_to_actuators(ul)
        lim = self.cfg.limits
        a1 = min(max(a1, lim.tilt_min_rad), lim.tilt_max_rad)
        a3 = min(max(a3, lim.tilt_min_rad), lim.tilt_max_rad)
        w1 = min(w1, lim.duct_speed_max)
        w3 = min(w3, lim.duct_speed_max)
        w2 = min(max(w2, -lim.tail_speed_max), lim.tail_speed_max)
        out = IndiOutput((a1, a3), (w1, w2, w3), tuple(ul))
        status = IndiStatus(
            acc_filtered=tuple(acc_f),
            u0_filtered=tuple(u0),
            delta_acc=tuple(d_acc_l),
            delta_u=tuple(du.tolist()),
            saturation_scale=(scales[0], scales[1], scales[2]),
            saturated=any(s < 1.0 for s in scales),
            fallback_to_u0=fallback,
        )
        return out, status

    def _feasible(self, u: np.ndarray | list[float]) -> bool:
        u1, u2, u3, u4, u5 = u.tolist() if isinstance(u, np.ndarray) else u
        if not all(math.isfinite(v) for v in (u1, u2, u3, u4, u5)):
            return False
        if u1 * u1 + u2 * u2 > self._w_duct_sq_max**2 or u3 * u3 + u4 * u4 > self._w_duct_sq_max**2:
            return False
        if abs(u5) > self._w_tail_sq_max:
            return False
        lim = self.cfg.limits
        for uc, us in ((u1, u2), (u3, u4)):
            if uc * uc + us * us > 1e-6:
                a = math.atan2(us, uc)
                if a < lim.tilt_min_rad or a > lim.tilt_max_rad:
                    return False
        return True

    def _max_scale(self, base: np.ndarray, part: np.ndarray, iters: int = 12) -> float:
        """Largest s in [0, 1] with base + s*part feasible (bisection; 0 if base alone is infeasible)."""
        if not self._feasible(base):
            return 0.0
        lo, hi = 0.0, 1.0
        for _ in range(iters):
            mid = 0.5 * (lo + hi)
            if self._feasible(base + mid * part):
                lo = mid
            else:
                hi = mid
        return lo


class IndiController(IndiControllerReference):
    """IndiControllerReference with the tick in one numba kernel (navig8_fc/core/_kernels.indi_step).

    Filter state lives in a flat float64 array; same arithmetic up to rounding (summation order of the
    5x5 products). Same inputs, outputs and status records.
    """

    def __init__(self, cfg: IndiConfig) -> None:
        super().__init__(cfg)
        lim = cfg.limits
        self._st = np.zeros(_k.N_ST)
        self._ic = np.array([
            lpf_alpha(cfg.lpf_tau_s, cfg.dt_s), 1.0 / cfg.dt_s, lim.tilt_min_rad, lim.tilt_max_rad,
            lim.duct_speed_max, lim.tail_speed_max, self._w_duct_sq_max**2, self._w_tail_sq_max,
        ])
        self._out = np.zeros(_k.N_IO)

    def reset(self) -> None:
        super().reset()
        self._st[:] = 0.0

    def measure(self, inp: IndiInputs) -> tuple[list[float], list[float]]:
        sf, (a1, a3), (w1, w2, w3) = inp.specific_force_frd, inp.tilt_rad, inp.speed_rad_s
        _k.indi_measure(self._st, self._ic, np.asarray(inp.gyro_frd, dtype=float), float(sf[0]), float(sf[2]),
                        float(a1), float(a3), float(w1), float(w2), float(w3), self._out)
        o = self._out.tolist()
        return o[0:5], o[5:10]

    def step(self, inp: IndiInputs) -> tuple[IndiOutput, IndiStatus]:
        sf, (a1, a3), (w1, w2, w3) = inp.specific_force_frd, inp.tilt_rad, inp.speed_rad_s
        gc_inv = inp.gc_inv if inp.gc_inv is not None else np.linalg.inv(inp.gc)
        return self._step(np.asarray(inp.gyro_frd, dtype=float), float(sf[0]), float(sf[2]), float(a1), float(a3),
                          float(w1), float(w2), float(w3), np.asarray(inp.accel_cmd, dtype=float), gc_inv, inp.gi_hat)

    def _step(
        self, gyro: np.ndarray, sf_x: float, sf_z: float, a1: float, a3: float, w1: float, w2: float, w3: float,
        accel_cmd: np.ndarray, gc_inv: np.ndarray, gi_hat: np.ndarray,
    ) -> tuple[IndiOutput, IndiStatus]:
        """step() on its inputs already converted (float64 arrays, Python floats); the controller's tick."""
        out = self._out
        _k.indi_step(self._st, self._ic, gyro, sf_x, sf_z, a1, a3, w1, w2, w3, accel_cmd, gc_inv, gi_hat, out)
        o = tuple(out.tolist())
        s0, s1, s2 = scales = o[25:28]
        res = IndiOutput(o[29:31], o[31:34], o[20:25])
        status = IndiStatus(
            acc_filtered=o[0:5],
            u0_filtered=o[5:10],
            delta_acc=o[10:15],
            delta_u=o[15:20],
            saturation_scale=scales,
            saturated=s0 < 1.0 or s1 < 1.0 or s2 < 1.0,
            fallback_to_u0=o[28] != 0.0,
        )
        return res, status
