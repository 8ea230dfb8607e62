"""Exogenous signals (waves, sensor noise) produced in blocks of steps, per boat.

A step of an environment then costs one gather per signal instead of a few array operations,
and the signals of many boats are produced together. Each boat has its own cursor: boats reset
at different times (vector environments) still see their signal from its start, so a boat's
signal never depends on what the other boats of the batch do.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

#: Steps per block.
BLOCK = 256

Fill = Callable[[NDArray[np.intp]], NDArray[np.float64]]


class BlockStream:
    """Rows of a per-boat signal, refilled ``BLOCK`` steps at a time.

    :param width: values per step and boat.
    :param fill: given boat indices ``idx``, returns their next blocks, shape
        ``(len(idx), BLOCK, width)``; it is called at reset and whenever a block is used up.
    """

    def __init__(self, width: int, fill: Fill) -> None:
        self.width, self.fill = width, fill

    def bind(self, batch_size: int) -> None:
        """Allocate blocks for ``batch_size`` boats."""
        self.blocks = np.zeros((batch_size, BLOCK, self.width))
        self.rows = self.blocks.reshape(batch_size * BLOCK, self.width)  # a view
        self.first_row = np.arange(batch_size) * BLOCK
        self.cursor = self.first_row.copy()
        self._one = np.ones(1, dtype=self.cursor.dtype)
        self._countdown = BLOCK  # steps until the first boat runs out

    def __getstate__(self) -> dict:
        # a copy of `rows` would no longer be a view of `blocks` (refills would not show)
        state = self.__dict__.copy()
        state.pop("rows", None)
        return state

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        if "blocks" in state:
            self.rows = self.blocks.reshape(-1, self.width)

    def restart(self, idx: NDArray[np.intp]) -> None:
        """Refill boats ``idx`` from their signal's current state (call at episode start)."""
        self._refill(idx)

    def next(self) -> NDArray[np.float64]:
        """The current row of every boat (batch x width, a new array); then advance."""
        if self.rows.shape[0] == BLOCK:
            # a batch of one (single environments): basic slicing beats index arrays
            row = int(self.cursor[0])
            values = self.rows[row:row + 1].copy()
            self.cursor[0] = row + 1
        else:
            values = self.rows.take(self.cursor, axis=0)
            self.cursor = self.cursor + self._one  # array operands: cheaper than += 1
        self.advanced()
        return values

    def refill_exhausted(self) -> None:
        """Refill the boats whose block compiled code used up (it reads ``rows[cursor]`` and
        moves ``cursor`` itself)."""
        self._refill(np.flatnonzero(self.cursor - self.first_row == BLOCK))

    def advanced(self) -> None:
        """Account for one row of every boat taken by compiled code, which read ``rows[cursor]``
        and advanced ``cursor`` itself (what :meth:`next` does, but the reading)."""
        self._countdown -= 1
        if self._countdown == 0:
            self._refill(np.flatnonzero(self.cursor - self.first_row == BLOCK))

    def _refill(self, idx: NDArray[np.intp]) -> None:
        if idx.size:
            self.blocks[idx] = self.fill(idx)
            self.cursor[idx] = self.first_row[idx]
        self.recount()

    def recount(self) -> None:
        """Count the steps until the first boat runs out anew (after compiled code moved the
        cursors, which keeps no count)."""
        self._countdown = BLOCK - int((self.cursor - self.first_row).max())
