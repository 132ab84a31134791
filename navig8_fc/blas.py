"""One BLAS thread in Navig8's processes: the FC's and the plant's matrices are at most tens wide, and OpenBLAS runs its
LU solves threaded at any size, so on a busy machine (a GCS, a second SITL, a campaign's workers, the test lanes) each
small LAPACK call waits for a core: a 3x3 `expm` 20 ms against 0.04 ms with one thread (docs/results.md, "Speed").

- `ONE_THREAD_ENV`: the environment that does it for a process not yet started, or for this one before numpy loads.
- `limit_to_one_thread`: for this process once numpy has loaded (threadpoolctl sets every BLAS it finds).

No numpy here: importing this module must not load the library it configures.
"""

from __future__ import annotations

ONE_THREAD_ENV = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


def limit_to_one_thread() -> None:
    """Every BLAS loaded in this process to one thread, for the process's life."""
    from threadpoolctl import threadpool_limits

    threadpool_limits(limits=1, user_api="blas")
