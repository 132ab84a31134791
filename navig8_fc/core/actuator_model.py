"""The FC's model of its actuators (paper Sec. 3.1, Eq. 10): each of the five (alpha1, alpha3, w1, w2, w3) is
x'' = wn^2 (u - x) - 2 zeta wn x', the command held over each control period (zero-order hold), discretised
exactly: [x, x']_{k+1} = Ad [x, x']_k + Bd u_k, by the matrix exponential of the augmented system.

Used by the INDI's model-based U0 (INDI_U0_SRC = 1, `indi.actuator_estimate`) and by the PX4 simulator interface
when no actuator measurements arrive (navig8_fc.mavlink.px4sim). The step itself is one numba kernel
(`actuator_model_step`), shared by both. Pure: no I/O.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numba import njit

from navig8_fc.core.layout import layout

N_ACTUATORS = 5


def actuator_discretisation(wn_rad_s: float, zeta: float, dt_s: float) -> tuple[np.ndarray, np.ndarray]:
    """(Ad as [a00, a01, a10, a11], Bd as [b0, b1]) of the second-order lag y'' = wn^2 (u - y) - 2 zeta wn y' under a
    zero-order-hold command: Ad = exp(A dt) in closed form (a 2x2 matrix with eigenvalues s +- d, s = -zeta wn dt,
    d^2 = (wn dt)^2 (zeta^2 - 1): exp(M) = e^s (c I + g (M - s I)), c = cosh d or cos |d|, g = sinh(d) / d or
    sin|d| / |d|), and Bd = A^-1 (Ad - I) B with B = [0, wn^2] (A is invertible for wn > 0), which is
    [1 - a00, -a10]. Closed form rather than scipy.linalg.expm: the same numbers within 1e-12
    (tests/unit/test_actuator_discretisation.py checks them against scipy) without scipy.linalg's import (~0.25 s of
    CPU at every FC and bridge start)."""
    if not (wn_rad_s > 0.0 and zeta > 0.0 and dt_s > 0.0):
        raise ValueError(f"actuator model needs wn, zeta, dt > 0, got {wn_rad_s}, {zeta}, {dt_s}")
    w = wn_rad_s * dt_s  # the dimensionless step
    s = -zeta * w
    disc = w * w * (zeta * zeta - 1.0)
    if disc > 0.0:  # overdamped: real eigenvalues
        d = math.sqrt(disc)
        c, g = math.cosh(d), math.sinh(d) / d
    elif disc < 0.0:  # underdamped: complex pair
        d = math.sqrt(-disc)
        c, g = math.cos(d), math.sin(d) / d
    else:  # critically damped: a double eigenvalue
        c, g = 1.0, 1.0
    e = math.exp(s)
    # M = A dt = [[0, dt], [-wn^2 dt, -2 zeta wn dt]]; M - s I = [[-s, dt], [-wn^2 dt, -2 zeta wn dt - s]]
    a00 = e * (c - g * s)
    a01 = e * g * dt_s
    a10 = -e * g * wn_rad_s * wn_rad_s * dt_s
    a11 = e * (c + g * (-2.0 * zeta * w - s))
    # A^-1 (Ad - I) B = [1 - a11 - 2 zeta wn a01, wn^2 a01] = [1 - a00, -a10]: from rest at 0, a held unit command
    b0, b1 = 1.0 - a00, -a10
    return np.array([a00, a01, a10, a11]), np.array([b0, b1])


def group_discretisation(wn_tilt_rad_s: float, wn_speed_rad_s: float, zeta: float, dt_s: float
                         ) -> tuple[np.ndarray, np.ndarray]:
    """The (Ad (8), Bd (4)) pair `actuator_model_step` takes: the tilts' group, then the speeds'."""
    ad_t, bd_t = actuator_discretisation(wn_tilt_rad_s, zeta, dt_s)
    ad_s, bd_s = actuator_discretisation(wn_speed_rad_s, zeta, dt_s)
    return np.concatenate([ad_t, ad_s]), np.concatenate([bd_t, bd_s])


@njit(cache=True)
def actuator_model_step(x, xo, ad, bd, cmd, co):
    """The five actuators' state x[xo:xo + 5] (positions), x[xo + 5:xo + 10] (rates) advanced one period under
    the held command cmd[co:co + 5]: [p, r] <- Ad [p, r] + Bd u (Eq. 10's second-order lag, exact ZOH;
    per group g (0: the tilts alpha1, alpha3; 1: the speeds w1, w2, w3) ad[4 g:4 g + 4] = [a00, a01, a10, a11],
    bd[2 g:2 g + 2] = [b0, b1] from actuator_discretisation)."""
    for i in range(5):
        g = 0 if i < 2 else 1
        p, r, u = x[xo + i], x[xo + 5 + i], cmd[co + i]
        x[xo + i] = ad[4 * g] * p + ad[4 * g + 1] * r + bd[2 * g] * u
        x[xo + 5 + i] = ad[4 * g + 2] * p + ad[4 * g + 3] * r + bd[2 * g + 1] * u


class ActuatorModel:
    """The five actuators' (position, rate) state, advanced one period per `step(command)`."""

    def __init__(self, wn_rad_s: float, zeta: float, dt_s: float, initial: Sequence[float]) -> None:
        self._ad, self._bd = group_discretisation(wn_rad_s, wn_rad_s, zeta, dt_s)
        self._x = np.zeros(2 * N_ACTUATORS)  # positions, then rates (the kernel's layout)
        self._x[:N_ACTUATORS] = np.asarray(initial, dtype=float)

    def step(self, command: Sequence[float]) -> tuple[float, ...]:
        """Advance one period under `command`; the positions after it."""
        actuator_model_step(self._x, 0, self._ad, self._bd, np.asarray(command, dtype=float), 0)
        return self.positions

    @property
    def positions(self) -> tuple[float, ...]:
        return tuple(self._x[:N_ACTUATORS].tolist())

    @property
    def rates(self) -> tuple[float, ...]:
        return tuple(self._x[N_ACTUATORS:].tolist())


class DeliveredU:
    """U (Sec. 3) of what the actuators deliver under the commands flown, by this model (the adaptive law's
    CKF_U_SRC = 2): each command advances the five actuators one period (positions seeded by the first command), and
    U is taken of their positions, so the law's U lags the command as the actuators do, in actuator space (U is
    cos(alpha) w^2 and sin(alpha) w^2 of them)."""

    def __init__(self, wn_rad_s: float, zeta: float, dt_s: float) -> None:
        self._ad, self._bd = group_discretisation(wn_rad_s, wn_rad_s, zeta, dt_s)
        self._x = np.zeros(2 * N_ACTUATORS)
        self._cmd = np.zeros(N_ACTUATORS)

    def step(self, tilt: Sequence[float], speed: Sequence[float], u_out: np.ndarray, seed: bool) -> None:
        """Advance under the command (tilts alpha1, alpha3; speeds w1, w2, w3) and write U of the positions to u_out;
        seed: start from the command, at rest (the first command, or the first after the motors were off)."""
        c = self._cmd
        c[0], c[1], c[2], c[3], c[4] = tilt[0], tilt[1], speed[0], speed[1], speed[2]
        if seed:
            self._x[:N_ACTUATORS] = c
            self._x[N_ACTUATORS:] = 0.0
        actuator_model_step(self._x, 0, self._ad, self._bd, c, 0)
        a1, a3, w1, w2, w3 = self._x[:N_ACTUATORS].tolist()
        u_out[0], u_out[1] = math.cos(a1) * w1 * w1, math.sin(a1) * w1 * w1
        u_out[2], u_out[3] = math.cos(a3) * w3 * w3, math.sin(a3) * w3 * w3
        u_out[4] = math.copysign(w2 * w2, w2)


# ---------------------------------------------------------------------------------------------
# Online identification of the actuators' bandwidth (INDI_U0_SRC = 1, ACT_ID = 1)
# ---------------------------------------------------------------------------------------------
# The model-based U0 is only as good as its model of the actuators (ACT_WN). A bank of three copies of the model per
# group (tilts, speeds), at omega_n x {1/r, 1, r} around the current estimate on a log grid, is run on the command
# flown and corrected toward the measurement like the INDI's own estimate; the exponentially weighted mean squared
# one-step innovation J of each copy says which omega_n explains the measurement best, and the estimate climbs the
# grid toward the lower J (a multiple-model hill climb: no gradient of the exact discretisation needed, and every
# bank member is a stable exact second-order model). The sensor noise is the same for all three copies, so it
# cancels in the comparison; J differs only where the actuators move (transients), which is what identifies omega_n.
ID_GRID_MIN, ID_GRID_MAX, ID_GRID_STEP = 0.4, 2.5, 1.05  # omega_n / ACT_WN of the grid, and its ratio per index
ID_SIDE = 3  # the side copies sit ID_SIDE grid steps away (x 1.05^3 = 1.16)
ID_J_TAU_S = 2.0  # time constant of the innovation averages
ID_EVAL_S = 0.5  # how often the estimate may move, one side step at a time
ID_HYST = 0.02  # a side copy must beat the middle one's J by this share
# State: the three copies' actuator states (positions 5, rates 5 each), J per group and copy, the grid index per
# group, ticks since the last move, whether the copies have a state, the number of moves (an edge for the shell).
AID = layout("AID", x=30, j=6, idx=2, ticks=1, ok=1, moves=1)


def id_grid(wn_rad_s: float, zeta: float, dt_s: float) -> np.ndarray:
    """The identification grid: row i = [Ad (4), Bd (2), omega_n] at omega_n = ACT_WN * ID_GRID_STEP^(i - i0)."""
    lo = math.floor(math.log(ID_GRID_MIN) / math.log(ID_GRID_STEP))
    hi = math.ceil(math.log(ID_GRID_MAX) / math.log(ID_GRID_STEP))
    rows = []
    for i in range(lo, hi + 1):
        w = wn_rad_s * ID_GRID_STEP**i
        ad, bd = actuator_discretisation(w, zeta, dt_s)
        rows.append(np.concatenate([ad, bd, [w]]))
    return np.ascontiguousarray(rows)


def id_state(grid: np.ndarray, wn_rad_s: float) -> np.ndarray:
    """A fresh identification state at the grid index nearest ACT_WN for both groups."""
    st = AID.zeros()
    i0 = int(np.argmin(np.abs(grid[:, 6] - wn_rad_s)))
    st[AID.IDX] = i0
    st[AID.IDX + 1] = i0
    return st


@njit(cache=True)
def actuator_identify(st: np.ndarray, grid: np.ndarray, cmd: np.ndarray, meas: np.ndarray, gain: float,
                      dt_s: float) -> bool:
    """One control tick of the bank (module comment above): advance the three copies per group under cmd (the
    command flown over the last period), accumulate their innovations against meas (alpha1, alpha3, w1, w2, w3),
    correct them with the complementary gain, and every ID_EVAL_S move the group's estimate one side step toward a
    copy whose J is lower by ID_HYST. Returns True when an estimate moved (the caller re-discretises the U0 model).
    Before the first call, and after `st[AID.OK] = 0`, the copies start at the measurement."""
    n = grid.shape[0]
    if st[AID.OK] < 0.5:
        for m in range(3):
            for i in range(5):
                st[AID.X + 10 * m + i] = meas[i]
                st[AID.X + 10 * m + 5 + i] = 0.0
        st[AID.OK] = 1.0
        return False
    a = dt_s / ID_J_TAU_S
    for g in range(2):
        i_lo, i_hi = (0, 2) if g == 0 else (2, 5)
        centre = int(st[AID.IDX + g])
        for m in range(3):
            r = min(max(centre + (m - 1) * ID_SIDE, 0), n - 1)
            e2 = 0.0
            for i in range(i_lo, i_hi):
                o = AID.X + 10 * m
                p, v, u = st[o + i], st[o + 5 + i], cmd[i]
                p1 = grid[r, 0] * p + grid[r, 1] * v + grid[r, 4] * u
                v1 = grid[r, 2] * p + grid[r, 3] * v + grid[r, 5] * u
                e = meas[i] - p1
                e2 += e * e
                st[o + i] = p1 + gain * e
                st[o + 5 + i] = v1
            jj = AID.J + 3 * g + m
            st[jj] += a * (e2 - st[jj])
    st[AID.TICKS] += 1.0
    if st[AID.TICKS] * dt_s < ID_EVAL_S:
        return False
    st[AID.TICKS] = 0.0
    moved = False
    for g in range(2):
        j_lo, j_mid, j_hi = st[AID.J + 3 * g], st[AID.J + 3 * g + 1], st[AID.J + 3 * g + 2]
        centre = int(st[AID.IDX + g])
        step = 0
        if j_lo < (1.0 - ID_HYST) * j_mid and j_lo <= j_hi and centre - ID_SIDE >= 0:
            step = -ID_SIDE
        elif j_hi < (1.0 - ID_HYST) * j_mid and centre + ID_SIDE <= n - 1:
            step = ID_SIDE
        if step != 0:
            st[AID.IDX + g] = centre + step
            # the copy that won becomes the middle one; the others continue from its state
            src = 0 if step < 0 else 2
            i_lo, i_hi = (0, 2) if g == 0 else (2, 5)
            for m in range(3):
                if m != src:
                    for i in range(i_lo, i_hi):
                        st[AID.X + 10 * m + i] = st[AID.X + 10 * src + i]
                        st[AID.X + 10 * m + 5 + i] = st[AID.X + 10 * src + 5 + i]
            jw = st[AID.J + 3 * g + src]
            for m in range(3):
                st[AID.J + 3 * g + m] = jw
            moved = True
    if moved:
        st[AID.MOVES] += 1.0
    return moved


__all__ = ["N_ACTUATORS", "ActuatorModel", "actuator_discretisation", "group_discretisation", "id_grid", "id_state",
           "actuator_identify", "AID"]
