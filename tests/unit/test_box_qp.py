"""navig8_fc.core.box_qp: min (x - x_hat)^T W (x - x_hat) s.t. lower <= x <= upper.

Independent checks: scipy's bounded-variable least squares (BVLS) on the Cholesky-transformed problem
(W = L L^T, so the cost is ||L^T x - L^T x_hat||^2), the KKT conditions evaluated here with numpy, and closed
forms (W = I is clipping; a 2-D correlated W). The solver (active-set iteration) and its fallback
(enumeration of the faces) are each checked against BVLS, not against each other.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import lsq_linear

from navig8_fc.core import box_qp
from navig8_fc.core.box_qp import project_box, project_box_exact

BVLS_RTOL = 1e-6  # relative to max(1, |x|): BVLS's own tolerance on problems with cond(W) <= 1e4
KKT_RTOL = 1e-8  # largest KKT violation relative to the gradient's scale


def _random_spd(rng: np.random.Generator, n: int, max_log_cond: float = 4.0) -> np.ndarray:
    """Random SPD matrix with condition number 10^U(0, max_log_cond) and random orientation and scale."""
    qm, _ = np.linalg.qr(rng.normal(size=(n, n)))
    eig = 10.0 ** rng.uniform(0.0, max_log_cond, n)
    scale = 10.0 ** rng.uniform(-3.0, 3.0)
    w = scale * (qm * eig) @ qm.T
    return 0.5 * (w + w.T)


def _random_problem(rng: np.random.Generator, n: int = 4) -> tuple[np.ndarray, ...]:
    w = _random_spd(rng, n)
    centre = rng.uniform(-5.0, 5.0, n)
    half = 10.0 ** rng.uniform(-2.0, 1.0, n)
    lo, hi = centre - half, centre + half
    # Points inside, just outside and far outside, per component.
    spread = rng.choice([0.5, 1.5, 5.0], size=n)
    x_hat = centre + half * spread * rng.uniform(-1.0, 1.0, n)
    return x_hat, w, lo, hi


def _outside_problems(seed: int, count: int) -> list[tuple[np.ndarray, ...]]:
    rng = np.random.default_rng(seed)
    out = []
    while len(out) < count:
        x_hat, w, lo, hi = _random_problem(rng)
        if not np.all((x_hat >= lo) & (x_hat <= hi)):
            out.append((x_hat, w, lo, hi))
    return out


def _bvls_projection(x_hat: np.ndarray, w: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Independent reference: min ||L^T (x - x_hat)||^2 with W = L L^T, by scipy's BVLS."""
    lt = np.linalg.cholesky(w).T
    res = lsq_linear(lt, lt @ x_hat, bounds=(lo, hi), method="bvls", tol=1e-14)
    return res.x


def _kkt_residual(x: np.ndarray, x_hat: np.ndarray, w: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> float:
    """Largest violation of the box-QP optimality conditions (g = W (x - x_hat) = 0 on free components,
    >= 0 at a lower, <= 0 at an upper bound), relative to |W| |x - x_hat|."""
    g = w @ (x - x_hat)
    scale = float(np.abs(w).max() * max(np.abs(x - x_hat).max(), 1e-300))
    width = hi - lo
    at_lo = x <= lo + 1e-12 * (1.0 + width)
    at_hi = x >= hi - 1e-12 * (1.0 + width)
    viol = np.where(at_lo & ~at_hi, np.maximum(-g, 0.0), np.where(at_hi & ~at_lo, np.maximum(g, 0.0), np.abs(g)))
    viol = np.where(at_lo & at_hi, 0.0, viol)
    return float(viol.max()) / scale if scale > 0 else 0.0


def _check_against_oracles(x: np.ndarray, x_hat: np.ndarray, w: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> None:
    assert np.all(x >= lo) and np.all(x <= hi), "projection left the box"
    ref = _bvls_projection(x_hat, w, lo, hi)
    assert np.max(np.abs(x - ref)) <= BVLS_RTOL * max(1.0, float(np.abs(ref).max()))
    assert _kkt_residual(x, x_hat, w, lo, hi) < KKT_RTOL


def test_projection_matches_bvls_and_kkt() -> None:
    """project_box (active set from the clip face, enumeration fallback) vs BVLS on 500 random problems with
    x_hat outside; the active-set iteration alone certifies nearly all of them."""
    n_fallback = 0
    for x_hat, w, lo, hi in _outside_problems(11, 500):
        res = project_box(x_hat, w, lo, hi)
        assert res.projected
        _check_against_oracles(res.x, x_hat, w, lo, hi)
        n_fallback += res.used_fallback
        assert res.used_fallback == (res.iterations == 0)
    assert n_fallback <= 5  # measured: 10 in 2000 (0.5 %)


def test_projection_with_w_inverse_gives_the_same_point() -> None:
    """Passing W^-1 (the KF has P) only changes how a face is solved, not the answer."""
    for x_hat, w, lo, hi in _outside_problems(8, 200):
        a = project_box(x_hat, w, lo, hi, w_inv=np.linalg.inv(w)).x
        _check_against_oracles(a, x_hat, w, lo, hi)


def test_enumeration_fallback_matches_bvls_and_kkt() -> None:
    for x_hat, w, lo, hi in _outside_problems(12, 300):
        _check_against_oracles(project_box_exact(x_hat, w, lo, hi), x_hat, w, lo, hi)


def test_fallback_answers_when_the_active_set_iteration_gives_no_certificate() -> None:
    """Problems on which the active-set iteration does not certify a face within MAX_ITER (found by search):
    project_box reports the fallback, and its answer is still the BVLS optimum."""
    found = 0
    x = np.empty(4)
    for x_hat, w, lo, hi in _outside_problems(0, 2000):
        if box_qp.active_set_solve(x_hat, w, w, False, lo, hi, x, box_qp.MAX_ITER) > 0:
            continue
        found += 1
        res = project_box(x_hat, w, lo, hi)
        assert res.used_fallback and res.iterations == 0
        _check_against_oracles(res.x, x_hat, w, lo, hi)
    assert found >= 1


def test_certified_answers_pass_kkt_for_any_iteration_limit() -> None:
    """Whatever the iteration limit, a certified (> 0) answer is the optimum; a cut-short one says so (0)."""
    for x_hat, w, lo, hi in _outside_problems(21, 200):
        for max_iter in (1, 2, 3):
            x = np.empty(4)
            it = box_qp.active_set_solve(x_hat, w, w, False, lo, hi, x, max_iter)
            assert 0 <= it <= max_iter
            if it:
                _check_against_oracles(x, x_hat, w, lo, hi)


def test_python_path_is_the_kernels_py_func() -> None:
    """The plain-Python path (numba's py_func of the same code) gives the compiled answers to rounding."""
    for x_hat, w, lo, hi in _outside_problems(5, 30):
        x_c, x_p = np.empty(4), np.empty(4)
        code_c = box_qp.solve(x_hat, w, w, False, lo, hi, x_c)
        code_p = box_qp.solve.py_func(x_hat, w, w, False, lo, hi, x_p)
        assert code_c == code_p
        np.testing.assert_allclose(x_p, x_c, rtol=1e-12, atol=1e-12)
        e_c, e_p = np.empty(4), np.empty(4)
        assert box_qp.enumerate_faces(x_hat, w, lo, hi, e_c) and box_qp.enumerate_faces.py_func(x_hat, w, lo, hi, e_p)
        np.testing.assert_allclose(e_p, e_c, rtol=1e-12, atol=1e-12)


def test_identity_weight_is_clipping() -> None:
    rng = np.random.default_rng(2)
    eye = np.eye(4)
    for _ in range(200):
        x_hat, _, lo, hi = _random_problem(rng)
        clipped = np.clip(x_hat, lo, hi)
        res = project_box(x_hat, eye, lo, hi)
        np.testing.assert_array_equal(res.x, clipped)
        assert res.iterations in (0, 1)  # the clip face is optimal at once
        np.testing.assert_array_equal(project_box_exact(x_hat, eye, lo, hi), clipped)


def test_minimum_variance_projection_is_not_clipping() -> None:
    """With correlated W = P^-1, holding one bound shifts the other component by P_21/P_11 times the move
    (closed form: x2 = x_hat2 + P21/P11 (1 - 2) = -0.5)."""
    p = np.array([[1.0, 0.5], [0.5, 1.0]])
    w = np.linalg.inv(p)
    args = ([2.0, 0.0], w, [-10.0, -10.0], [1.0, 10.0])
    np.testing.assert_allclose(project_box(*args).x, [1.0, -0.5], rtol=0, atol=1e-12)
    np.testing.assert_allclose(project_box(*args, w_inv=p).x, [1.0, -0.5], rtol=0, atol=1e-12)
    np.testing.assert_allclose(project_box_exact(*args), [1.0, -0.5], rtol=0, atol=1e-12)


def test_inside_point_is_returned_and_bad_inputs_raise() -> None:
    x = np.array([1.0, 2.0, 3.0, 4.0])
    lo, hi = x - 1.0, x + 1.0
    w = np.eye(4)
    res = project_box(x, w, lo, hi)
    assert not res.projected and not res.used_fallback and np.array_equal(res.x, x)
    assert np.array_equal(project_box_exact(x, w, lo, hi), x)
    with pytest.raises(ValueError):
        project_box(x, w, hi, lo)  # empty box
    with pytest.raises(ValueError):
        project_box_exact(x, w, hi, lo)
    with pytest.raises(ValueError):
        project_box(x, np.eye(3), lo, hi)
    with pytest.raises(ValueError):
        project_box(x, w, lo, [np.nan, 1.0, 1.0, 1.0])


def test_degenerate_box_lower_equals_upper() -> None:
    rng = np.random.default_rng(4)
    w = _random_spd(rng, 4)
    lo = np.array([1.0, 2.0, 3.0, 4.0])
    hi = lo.copy()
    hi[2] += 1.0
    x_hat = np.array([0.0, 5.0, 10.0, 4.0])
    # Closed form (BVLS refuses lower == upper): components 0, 1, 3 are fixed; the cost is a parabola in x2
    # with its vertex at x_hat2 - sum_j W_2j (x_j - x_hat_j) / W_22 (j fixed), clipped to [3, 4].
    fixed = [0, 1, 3]
    x2 = x_hat[2] - w[2, fixed] @ (lo[fixed] - x_hat[fixed]) / w[2, 2]
    expected = np.array([1.0, 2.0, min(max(x2, lo[2]), hi[2]), 4.0])
    for x in (project_box(x_hat, w, lo, hi).x, project_box_exact(x_hat, w, lo, hi)):
        assert x[0] == 1.0 and x[1] == 2.0 and x[3] == 4.0 and lo[2] <= x[2] <= hi[2]
        np.testing.assert_allclose(x, expected, rtol=0, atol=1e-12 * max(1.0, abs(x2)))
