"""One BLAS thread for every run, whatever the process has imported so far.

A multi-threaded BLAS rounds differently (1e-9 relative after 30 views, enough to change a
MuJoCo episode's path), so every command and every campaign worker computes with one BLAS
thread: results are then identical in-process, across local workers and on Dask workers.
``threadpoolctl`` limits only the BLAS libraries already loaded, and ``import bve_mj`` loads
none (its names resolve on first use): SciPy's own BLAS, which the planner's optimiser and
the filters use, is loaded here first so that the limit reaches it.
"""

from __future__ import annotations

from contextlib import AbstractContextManager
from typing import Any

__all__ = ["one_blas_thread"]


def one_blas_thread() -> AbstractContextManager[Any]:
    """A context in which every BLAS the package computes with runs on one thread."""
    import scipy.linalg  # noqa: F401  (loads SciPy's BLAS before the limit is set)
    from threadpoolctl import threadpool_limits

    return threadpool_limits(limits=1, user_api="blas")
