"""Small dense linear algebra as numba kernels: partial pivoting and a Gauss-Jordan inverse for the 4x4 and 5x5
matrices of the controller's tick (G_C, the KF's covariance), where numpy's per-call overhead dominates.

Used by the model (g_c.uam_model, gc_inv_about), the box QP (box_qp) and the Kalman filter (kalman). Pure: no I/O.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from navig8_fc.core.jit import njit_cached


@njit_cached()  # one compilation whatever constant n a kernel passes (jit.py)
def pivot_rows(m, c, n):
    """Partial pivoting for column c of the n-row matrix m: swap the row (of c..n-1) with the largest |m[r, c]|
    into row c (all columns). False if that pivot is zero or not finite (m unchanged then)."""
    p = c
    big = abs(m[c, c])
    for r in range(c + 1, n):
        v = abs(m[r, c])
        if v > big:
            p = r
            big = v
    if big == 0.0 or not math.isfinite(big):
        return False
    if p != c:
        for j in range(m.shape[1]):
            t = m[c, j]
            m[c, j] = m[p, j]
            m[p, j] = t
    return True


@njit(cache=True)
def inv_gauss_jordan(a: np.ndarray, out: np.ndarray) -> bool:
    """out = a^-1 for a small square matrix (Gauss-Jordan, partial pivoting). False if singular."""
    n = a.shape[0]
    m = np.empty((n, 2 * n))
    for i in range(n):
        for j in range(n):
            m[i, j] = a[i, j]
            m[i, n + j] = 1.0 if i == j else 0.0
    for c in range(n):
        if not pivot_rows(m, c, n):
            return False
        piv = m[c, c]
        for j in range(2 * n):
            m[c, j] /= piv
        for r in range(n):
            if r != c:
                f = m[r, c]
                if f != 0.0:
                    for j in range(2 * n):
                        m[r, j] -= f * m[c, j]
    for i in range(n):
        for j in range(n):
            out[i, j] = m[i, n + j]
    return True
