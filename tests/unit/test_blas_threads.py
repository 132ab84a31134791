"""tools.blas_threads: one BLAS thread inside the block, each library's count back after it."""

from __future__ import annotations

import scipy.linalg  # noqa: F401 - maps SciPy's OpenBLAS beside NumPy's

from navig8_tools.blas_threads import blas_thread_counts, one_blas_thread


def test_one_blas_thread_inside_and_the_counts_back_after() -> None:
    before = blas_thread_counts()
    with one_blas_thread():
        assert blas_thread_counts() == [1] * len(before)
    assert blas_thread_counts() == before
