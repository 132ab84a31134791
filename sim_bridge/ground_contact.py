"""Ground contact of the plant (numba kernel): skid points on the flat NED z = 0 ground.

Per point in contact (docs/plant.md, "Ground contact"): normal force k depth + c z' clipped at >= 0 (the ground only
pushes) and Coulomb friction mu N v / sqrt(|v|^2 + v_eps^2), regularised below v_eps. The points, stiffness, damping
and friction are in the parameter vector (plant_layout.P: KN, CN, MU, VEPS, NC, CP). The arm is not part of it.
"""

from __future__ import annotations

import math

from numba import njit

from sim_bridge.plant_layout import P, X


@njit(inline="always")  # the step's hot path: inlined into its njit_cached callers
def contact_wrench(xb, p, wx, wy, wz, r):
    """Contact force (N, body FRD) and moment about O (N m) at the base state xb (X layout) with body rate w and
    R = r (body -> NED, rows, 9 entries): (fx, fy, fz, mx, my, mz, number of points touching)."""
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = r
    fcx = 0.0
    fcy = 0.0
    fcz = 0.0
    mcox = 0.0
    mcoy = 0.0
    mcoz = 0.0
    ncont = 0
    nc = int(p[P.NC])
    for i in range(nc):
        px = p[P.CP + 3 * i]
        py = p[P.CP + 3 * i + 1]
        pz = p[P.CP + 3 * i + 2]
        depth = xb[X.POS + 2] + r20 * px + r21 * py + r22 * pz
        if depth > 0.0:
            # point velocity in NED: v + R (w x p)
            ox = wy * pz - wz * py
            oy = wz * px - wx * pz
            oz = wx * py - wy * px
            vnx = xb[X.VEL] + r00 * ox + r01 * oy + r02 * oz
            vny = xb[X.VEL + 1] + r10 * ox + r11 * oy + r12 * oz
            vnz = xb[X.VEL + 2] + r20 * ox + r21 * oy + r22 * oz
            fn = p[P.KN] * depth + p[P.CN] * vnz
            if fn > 0.0:
                ncont += 1
                vt = math.sqrt(vnx * vnx + vny * vny + p[P.VEPS] * p[P.VEPS])
                ftx = -p[P.MU] * fn * vnx / vt
                fty = -p[P.MU] * fn * vny / vt
                ftz = -fn
                # NED -> body: R^T f
                fbx = r00 * ftx + r10 * fty + r20 * ftz
                fby = r01 * ftx + r11 * fty + r21 * ftz
                fbz = r02 * ftx + r12 * fty + r22 * ftz
                fcx += fbx
                fcy += fby
                fcz += fbz
                mcox += py * fbz - pz * fby
                mcoy += pz * fbx - px * fbz
                mcoz += px * fby - py * fbx
    return fcx, fcy, fcz, mcox, mcoy, mcoz, ncont
