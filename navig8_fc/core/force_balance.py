"""The held mass from the force balance, calibrated on the UAM's known mass (CKF_M_ABS_SIG).

Eq. 24's force rows read increments, Delta F = m Delta a, and so only what the excitation moves: through the
identification flight's doublets a window's Delta a_x carries ~0.03 m/s^2 of the accelerometer's noise against
~0.3 m/s^2 of excitation, and by 5 s after a grasp the mass is known to 0.1-0.2 kg. The whole force balance,
F = m f (the propulsive force and the specific force of the composite CoM, any motion), carries the object's weight
itself: 5 N for 0.5 kg against 0.04 m/s^2 of low-passed noise on 9.8. Its model term, the absolute force G_C[F, :] U,
is what INDI avoids; so it is used as a ratio, as PX4's hover-thrust estimator does: while the gripper is open the
UAM's mass is known, and the ratio m_UAM / (F.f / f.f) is learned (a thrust model off by a constant factor cancels);
while it is closed, k F.f / f.f is a measurement of m. docs/model.md, "Estimator".
"""

from __future__ import annotations

import math
from typing import Protocol

import numpy as np

from navig8_fc.core.kf_nuisance import NZ_COV, NZ_VAR, NZ_X

__all__ = ["ForceBalanceMass", "MassCorrectable", "correct_mass"]

# the calibration's weight: a running mean until this many windows, then a low-pass of as many
_CAL_WINDOWS = 40.0
_CAL_MIN_WINDOWS = 8.0  # windows with the gripper open before the ratio is trusted


class MassCorrectable(Protocol):
    def correct_mass(self, z_kg: float, r_kg2: float) -> None: ...


class ForceBalanceMass:
    """Low-passes the force balance's two sides with the law's own filter (alpha, running-mean start) and keeps the
    open-gripper calibration. Plain floats: 4 components per tick."""

    def __init__(self, alpha: float, sigma_kg: float) -> None:
        """alpha: the law's low-pass weight; sigma_kg: the measurement's sigma per correction (CKF_M_ABS_SIG)."""
        self._alpha = alpha
        self._r_kg2 = sigma_kg * sigma_kg
        self.reset()

    def tick(self, gc: np.ndarray, u: np.ndarray, acc_m: np.ndarray, correct: bool, closed: bool | None,
             m_uam_kg: float, kf: MassCorrectable) -> None:
        """The law's tick (AdaptiveLaw): the two sides low-passed (G_C (5, 5), U and Acc_m (5,)); at a correction,
        the calibration with the gripper open, the mass's scalar update of kf with it closed (unknown: neither)."""
        self.update(float(gc[3] @ u), float(gc[4] @ u), acc_m.item(3), acc_m.item(4))
        if not correct or closed is None:
            return
        if not closed:
            self.calibrate(m_uam_kg)
            return
        z = self.measured_mass_kg()
        if math.isfinite(z):
            kf.correct_mass(z, self._r_kg2)

    def reset(self) -> None:
        self._n = 0.0
        self._fx = self._fz = self._ax = self._az = 0.0
        self._k = math.nan  # m_UAM / (F.f / f.f) with the gripper open
        self._n_cal = 0.0

    def restart(self) -> None:
        """A grasp or a release (the law detects it): the low-passes restart from the next sample, so no window mixes
        the two masses; the open-gripper calibration is kept."""
        self._n = 0.0

    def update(self, force_x_n: float, force_z_n: float, acc_x_m_s2: float, acc_z_m_s2: float) -> None:
        """One tick: the model's propulsive force (body x, z; N) and the specific force of the estimated CoM
        (m/s^2, the law's Acc_m force rows)."""
        self._n += 1.0
        a = max(self._alpha, 1.0 / self._n)
        self._fx += a * (force_x_n - self._fx)
        self._fz += a * (force_z_n - self._fz)
        self._ax += a * (acc_x_m_s2 - self._ax)
        self._az += a * (acc_z_m_s2 - self._az)

    def ratio_kg(self) -> float:
        """F.f / f.f of the low-passed sides (kg); nan while f is near zero (free fall: no balance to read)."""
        ff = self._ax * self._ax + self._az * self._az
        if ff < 1.0:
            return math.nan
        return (self._fx * self._ax + self._fz * self._az) / ff

    def calibrate(self, m_uam_kg: float) -> None:
        """A window with the gripper open: the ratio's factor, m_UAM over it, averaged."""
        r = self.ratio_kg()
        if not (r > 0.0):
            return
        self._n_cal += 1.0
        w = 1.0 / min(self._n_cal, _CAL_WINDOWS)
        k = m_uam_kg / r
        self._k = k if self._n_cal == 1.0 else self._k + w * (k - self._k)

    def measured_mass_kg(self) -> float:
        """k F.f / f.f (kg) with the gripper closed; nan until calibrated."""
        if self._n_cal < _CAL_MIN_WINDOWS:
            return math.nan
        return self._k * self.ratio_kg()


def correct_mass(x: np.ndarray, p: np.ndarray, nz: np.ndarray, nx: np.ndarray, z_kg: float, r_kg2: float) -> None:
    """The scalar update z = m + v, var v = r_kg2, of x = [I_xx, I_yy, I_zz, m] (P = p) and of the two nuisance
    states held beside it (nz the pitch row's CoM error, nx the I_xz error; NZ_* layout, each a state while its
    variance is > 0): gain P[:, m] / (P[m, m] + r), in place. The nuisances' covariance with each other is taken as
    zero, as in kf_nuisance."""
    n = 4
    idx_c = idx_d = -1
    if nz[NZ_VAR] > 0.0:
        idx_c, n = n, n + 1
    if nx[NZ_VAR] > 0.0:
        idx_d, n = n, n + 1
    xa = np.empty(n)
    pa = np.zeros((n, n))
    xa[:4] = x
    pa[:4, :4] = p
    for idx, nu in ((idx_c, nz), (idx_d, nx)):
        if idx >= 0:
            xa[idx] = nu[NZ_X]
            pa[idx, idx] = nu[NZ_VAR]
            pa[:4, idx] = nu[NZ_COV:NZ_COV + 4]
            pa[idx, :4] = nu[NZ_COV:NZ_COV + 4]
    s = pa[3, 3] + r_kg2
    g = pa[:, 3] / s
    xa += g * (z_kg - xa[3])
    pa -= np.outer(g, g) * s
    pa = 0.5 * (pa + pa.T)
    x[:] = xa[:4]
    p[:, :] = pa[:4, :4]
    for idx, nu in ((idx_c, nz), (idx_d, nx)):
        if idx >= 0:
            nu[NZ_X] = xa[idx]
            nu[NZ_VAR] = pa[idx, idx]
            nu[NZ_COV:NZ_COV + 4] = pa[:4, idx]
