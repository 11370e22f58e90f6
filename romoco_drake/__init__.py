"""romoco-drake: reduced-order-model walking controllers for bipeds and humanoids on Drake.

Importing the package limits BLAS (numpy's OpenBLAS) to one thread in this process and the
processes it starts (Ray workers, the LCM rehearsal's robot), unless ``OPENBLAS_NUM_THREADS`` or
``OMP_NUM_THREADS`` is set: the loop's matrices have tens of rows, where waking BLAS worker threads
costs more than they save and takes a core from the simulator or the other process (README,
"Running on hardware over LCM").
"""

import os

__version__ = "0.1.0"

if not any(os.environ.get(name) for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")):
    os.environ["OPENBLAS_NUM_THREADS"] = "1"  # BLAS libraries loaded from now on, and child processes
    import numpy  # noqa: F401  (its BLAS must be loaded for threadpoolctl to find it)
    from threadpoolctl import threadpool_limits

    threadpool_limits(1, user_api="blas")  # numpy's, when it was imported before this package
