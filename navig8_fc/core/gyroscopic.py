"""The estimator's gyroscopic moment (CKF_GYRO): Euler's velocity term, which Eq. 24 leaves out.

About the composite CoM the body obeys M = I w' + w x (I w) (the plant integrates exactly that), and Eq. 24 keeps
only I Delta w'. Through the identification flight's doublets the windows' Delta (w x I w) is small against
I Delta w' but correlated with it: with the arm stretched (q1 60 deg, I_xz -0.2...-0.5 kg m^2) its yaw component
-I_xz q r follows the yaw doublets, and a least-squares fit of the plant's own moments and accelerations (low-passed
and windowed as the law does) gives I_zz 3 % low without it, exact with it (docs/model.md, "Estimator"). The term is
low-passed and windowed as the law's U and Acc_m are (the same weight, the same running-mean start,
the same windows: its channels of law_filters.lpf_increments), with the inertia the estimator holds at each tick,
and taken out of the measurement.
"""

from __future__ import annotations

__all__ = ["gyroscopic_moment"]


def gyroscopic_moment(p: float, q: float, r: float, ixx: float, iyy: float, izz: float,
                      ixz: float) -> tuple[float, float, float]:
    """w x (I w) (N m, body FRD) for I = [[ixx, 0, ixz], [0, iyy, 0], [ixz, 0, izz]] (the tensor's entries; the
    arm moves in the x-z plane, so I_xy = I_yz = 0) and w = (p, q, r) (rad/s)."""
    return (q * r * (izz - iyy) + ixz * p * q,
            p * r * (ixx - izz) + ixz * (r * r - p * p),
            p * q * (iyy - ixx) - ixz * q * r)
