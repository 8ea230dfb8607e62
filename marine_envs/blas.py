"""One BLAS thread for the matrix products inside an environment's step.

A step's products are small (a block of waves for the boats that just reset: tens of rows), so
BLAS threads cost more than they save: OpenBLAS's default two threads made the USV's wave
product 1.3x slower at N = 1024, and three times slower in SB3 stepping whenever another job
held a core. They also change the result: OpenBLAS splits a product between its threads by
rows, and a row's sum is rounded differently at the edge of a split, so the same seed gave
other last bits on a machine with another core count. :func:`one_blas_thread` runs a block
with every BLAS library numpy loaded limited to one thread (threadpoolctl), and restores the
user's setting after it: the environment never changes the threads of the user's own code.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from functools import cache
from typing import Any


@cache
def _blas_libraries() -> tuple[Any, ...]:
    """threadpoolctl's controllers of the BLAS libraries loaded (numpy's, at least); found once
    (a scan of the loaded libraries costs milliseconds)."""
    import numpy  # noqa: F401  (its BLAS is the one the products use: loaded before the scan)
    from threadpoolctl import ThreadpoolController

    return tuple(ThreadpoolController().select(user_api="blas").lib_controllers)


@contextlib.contextmanager
def one_blas_thread() -> Iterator[None]:
    """Run the block with one BLAS thread, then restore each library's own count (a few
    microseconds; nothing is set when a library already runs one thread). Not for blocks that
    other Python threads run at the same time: the setting is the library's, process-wide."""
    changed = []
    for library in _blas_libraries():
        threads = library.num_threads
        if threads != 1:
            library.set_num_threads(1)
            changed.append((library, threads))
    try:
        yield
    finally:
        for library, threads in changed:
            library.set_num_threads(threads)
