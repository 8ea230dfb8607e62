"""Exogenous signals (waves, sensor noise) produced in blocks of steps, per boat.

A step of an environment then costs one gather per signal instead of a few array operations,
and the signals of many boats are produced together. Each boat has its own cursor: boats reset
at different times (vector environments) still see their signal from its start, so a boat's
signal never depends on what the other boats of the batch do.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence

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
            self.recount()  # (compiled code may have moved the cursors without counting)

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


class BlockSource(ABC):
    """A per-boat signal made a block of steps at a time (a sea, a current, a wind, an event):
    :meth:`blocks` makes a boat's next ``BLOCK`` steps from its state, :meth:`start` begins its
    episode, and :attr:`stream` hands the rows out (to :meth:`step`, or straight to the
    environments' compiled step kernel). Sources side by side are one source
    (:class:`~marine_envs.sea.processes.Stacked`).

    :param width: values per step and boat.
    """

    def __init__(self, width: int) -> None:
        self.width = width
        #: The rows, a block at a time per boat (read by the compiled step kernel too).
        self.stream = BlockStream(width, self.blocks)

    def bind(self, batch_size: int) -> None:
        """Allocate state for ``batch_size`` boats."""
        self.bind_state(batch_size)
        self.stream.bind(batch_size)

    def reset(self, idx: NDArray[np.intp], rngs: Sequence[np.random.Generator]) -> None:
        """New episodes for boats ``idx`` (``rngs[i]`` is boat ``idx[i]``'s generator)."""
        self.start(idx, rngs)
        self.stream.restart(idx)

    def step(self) -> NDArray[np.float64]:
        """The current values of every boat (batch x width); then advance a step."""
        return self.stream.next()

    @abstractmethod
    def bind_state(self, batch_size: int) -> None:
        """Allocate the per-boat state :meth:`blocks` works from."""

    @abstractmethod
    def start(self, idx: NDArray[np.intp], rngs: Sequence[np.random.Generator]) -> None:
        """Begin the episodes of boats ``idx``: their state at time 0 (no block made yet)."""

    @abstractmethod
    def blocks(self, idx: NDArray[np.intp]) -> NDArray[np.float64]:
        """The next ``BLOCK`` steps of boats ``idx`` (boats x BLOCK x width); advances their
        state by a block."""
