"""The estimator's gyroscopic moment (CKF_GYRO): Euler's velocity term, which Eq. 24 leaves out.

About the composite CoM the body obeys M = I w' + w x (I w) (the plant integrates exactly that), and Eq. 24 keeps
only I Delta w'. Through the identification flight's doublets the windows' Delta (w x I w) is small against
I Delta w' but correlated with it: with the arm stretched (q1 60 deg, I_xz -0.2...-0.5 kg m^2) its yaw component
-I_xz q r follows the yaw doublets, and a least-squares fit of the plant's own moments and accelerations (low-passed
and windowed as the law does) gives I_zz 3 % low without it, exact with it (docs/model.md, "Estimator"). The term is
low-passed and windowed as the law's U and Acc_m are (lpf_increments: the same weight, the same running-mean start,
the same windows), with the inertia the estimator holds at each tick, and taken out of the measurement.
"""

from __future__ import annotations

__all__ = ["GyroscopicIncrement", "gyroscopic_moment"]


def gyroscopic_moment(p: float, q: float, r: float, ixx: float, iyy: float, izz: float,
                      ixz: float) -> tuple[float, float, float]:
    """w x (I w) (N m, body FRD) for I = [[ixx, 0, ixz], [0, iyy, 0], [ixz, 0, izz]] (the tensor's entries; the
    arm moves in the x-z plane, so I_xy = I_yz = 0) and w = (p, q, r) (rad/s)."""
    return (q * r * (izz - iyy) + ixz * p * q,
            p * r * (ixx - izz) + ixz * (r * r - p * p),
            p * q * (iyy - ixx) - ixz * q * r)


class GyroscopicIncrement:
    """The low-passed gyroscopic moment and its increment over the law's windows. Plain floats: 3 components."""

    def __init__(self, alpha: float, mean_start: bool) -> None:
        self._alpha = alpha
        self._mean_start = mean_start
        self.reset()

    def reset(self) -> None:
        self._n = 0.0
        self._y = [0.0, 0.0, 0.0]
        self._w = [0.0, 0.0, 0.0]

    def tick(self, moment: tuple[float, float, float], ready: bool) -> tuple[float, float, float] | None:
        """One tick's gyroscopic moment (N m); returns the window's increment when a window closed (ready, as
        lpf_increments' LO_READY), else None. The first sample sets the low-pass, as lpf_increments does."""
        y = self._y
        if self._n == 0.0:
            self._n = 1.0
            y[:] = moment
            self._w[:] = moment
            return None
        self._n += 1.0
        a = self._alpha
        if self._mean_start and 1.0 / self._n > a:
            a = 1.0 / self._n
        for i in range(3):
            y[i] += a * (moment[i] - y[i])
        if not ready:
            return None
        w = self._w
        d = (y[0] - w[0], y[1] - w[1], y[2] - w[2])
        w[:] = y
        return d
