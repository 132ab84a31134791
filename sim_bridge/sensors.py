"""The plant's sensors (numba kernel): truth + white Gaussian noise per group, each group on its own time grid.

docs/plant.md, "Sensors": every sample draws the same normals (NOISE), so a seed fixes the run bit for bit; a group
not due repeats its last sample. The accelerometer reads the specific force at O of the derived quantities
(plant_layout.D.SPF), the gyro the body rates; the gyro and accelerometer can carry a constant bias.
"""

from __future__ import annotations

import math

from navig8_fc.core.jit import njit_cached
from navig8_fc.core.layout import layout
from sim_bridge import plant_layout
from sim_bridge.plant_layout import D, X

# Sensor output vector s, the SensorBundle's fields in this order.
S = layout("S", gyro=3, acc=3, pos=3, vel=3, quat=4, duct=2, prop=3, jq=3, jqd=3)
N_S = int(S.SIZE)
# Noise draws per sample (N(0, 1)); the mocap attitude noise is a small rotation vector.
NOISE = layout("NOISE", gyro=3, acc=3, pos=3, vel=3, att=3, duct=2, prop=3, jq=3, jqd=3)
N_NOISE = int(NOISE.SIZE)
# Standard deviations per sensor group (params.SensorParams)
# (gyro_bias, acc_bias: a constant offset on every body axis, the campaigns' sensor-bias factor)
SIG = layout("SIG", gyro=1, acc=1, pos=1, vel=1, att=1, duct=1, prop=1, jq=1, jqd=1, gyro_bias=1, acc_bias=1)
N_SIG = int(SIG.SIZE)
# Sensor group bits (same values as messages.SensorField), bit i = group i of sense()'s schedule.
G_IMU = 1
G_MOCAP = 2
G_ACT = 4
G_JOINT = 8
N_GROUPS = 4


@njit_cached(plant_layout)
def sense(x, d, sig, noise, prev, t_us, due_us, period_us, out) -> int:
    """Sensor sample at t_us: truth + sigma * N(0,1) for the groups due now, previous values for the others.
    Returns the groups sampled (G_* bits). due_us, period_us (int64, one per group in G_* bit order): a group is
    due when t_us >= its due time, which then moves past t_us by whole periods.

    The mocap attitude noise is a small body-frame rotation q_meas = q (x) [1, dth/2] (renormalised).
    """
    groups = 0
    for i in range(N_GROUPS):
        if t_us >= due_us[i]:
            groups |= 1 << i
            due_us[i] += period_us[i] * ((t_us - due_us[i]) // period_us[i] + 1)
    for i in range(N_S):
        out[i] = prev[i]
    if groups & G_IMU:
        for i in range(3):
            out[S.GYRO + i] = x[X.RATE + i] + sig[SIG.GYRO_BIAS] + sig[SIG.GYRO] * noise[NOISE.GYRO + i]
            out[S.ACC + i] = d[D.SPF + i] + sig[SIG.ACC_BIAS] + sig[SIG.ACC] * noise[NOISE.ACC + i]
    if groups & G_MOCAP:
        for i in range(3):
            out[S.POS + i] = x[X.POS + i] + sig[SIG.POS] * noise[NOISE.POS + i]
            out[S.VEL + i] = x[X.VEL + i] + sig[SIG.VEL] * noise[NOISE.VEL + i]
        hx = 0.5 * sig[SIG.ATT] * noise[NOISE.ATT]
        hy = 0.5 * sig[SIG.ATT] * noise[NOISE.ATT + 1]
        hz = 0.5 * sig[SIG.ATT] * noise[NOISE.ATT + 2]
        qw, qx, qy, qz = x[X.QUAT], x[X.QUAT + 1], x[X.QUAT + 2], x[X.QUAT + 3]
        ow = qw - qx * hx - qy * hy - qz * hz
        ox = qw * hx + qx + qy * hz - qz * hy
        oy = qw * hy - qx * hz + qy + qz * hx
        oz = qw * hz + qx * hy - qy * hx + qz
        nq = math.sqrt(ow * ow + ox * ox + oy * oy + oz * oz)
        if ow < 0.0:
            nq = -nq  # keep w >= 0 (same rotation)
        out[S.QUAT] = ow / nq
        out[S.QUAT + 1] = ox / nq
        out[S.QUAT + 2] = oy / nq
        out[S.QUAT + 3] = oz / nq
    if groups & G_ACT:
        out[S.DUCT] = x[X.ACT] + sig[SIG.DUCT] * noise[NOISE.DUCT]
        out[S.DUCT + 1] = x[X.ACT + 1] + sig[SIG.DUCT] * noise[NOISE.DUCT + 1]
        out[S.PROP] = x[X.ACT + 2] + sig[SIG.PROP] * noise[NOISE.PROP]
        out[S.PROP + 1] = x[X.ACT + 3] + sig[SIG.PROP] * noise[NOISE.PROP + 1]
        out[S.PROP + 2] = x[X.ACT + 4] + sig[SIG.PROP] * noise[NOISE.PROP + 2]
    if groups & G_JOINT:
        for i in range(3):
            out[S.JQ + i] = x[X.Q + i] + sig[SIG.JQ] * noise[NOISE.JQ + i]
            out[S.JQD + i] = x[X.QD + i] + sig[SIG.JQD] * noise[NOISE.JQD + i]
    return groups
