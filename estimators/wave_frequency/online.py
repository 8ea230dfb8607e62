"""The online model-update loop: a state machine per data stream that collects windows until one
is accepted, then monitors the spectrum for a sea-state change."""

from __future__ import annotations

import dataclasses
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..base import as_batch
from .config import FloatArray, WaveFrequencyConfig, _check_window, _rows
from .spectrum import spectral_peak
from .window import WindowEstimate, _row_estimate, estimate_window

_MAX_MISSING = 0.1  # fraction of missing samples an online window may interpolate over


@dataclasses.dataclass
class WindowEvent:
    """One thing the state machine did, for logs and plots.

    :param row: the batch row.
    :param time: s since the row's reset (the end of the data used).
    :param kind: ``"accepted"``, ``"rejected"`` (window discarded) or ``"sea_change"``.
    :param omega: accepted frequencies, or the rejected estimate, or the spectral peak that
        fired the change detector, rad/s ``(3,)``.
    :param detail: the estimate (accepted/rejected windows) or the reason text.
    """

    row: int
    time: float
    kind: Literal["accepted", "rejected", "sea_change"]
    omega: FloatArray
    detail: WindowEstimate | str


class WaveFrequencyEstimator:
    """The DP wave-frequency patent's model-update loop, online, for a batch of ``N``
    independent data streams.

    Per row, a flag ``model_update`` (True after :meth:`reset`):

    * flag set (*estimating*): collect a fresh window; when full, run :func:`estimate_window`;
      accepted -> store the frequencies in :attr:`omega`, clear the flag; rejected -> discard it
      and collect the next window;
    * flag clear (*monitoring*): every ``monitor_every`` s, fit the spectrum of the last
      ``monitor_window`` s; if its peak is more than ``threshold`` from :attr:`omega` in any DOF
      on ``change_confirmations`` checks in a row, the sea has changed: set the flag again.

    :param config: the pipeline's settings (its ``dt`` is the period of :meth:`push`).
    :param batch_size: number of streams ``N``.
    """

    def __init__(self, config: WaveFrequencyConfig | None = None, batch_size: int = 1) -> None:
        self.config = config or WaveFrequencyConfig()
        c = self.config
        self.window_samples = round(c.window / c.dt)
        self.monitor_samples = min(round(c.monitor_window / c.dt), self.window_samples)
        self.check_samples = max(1, round(c.monitor_every / c.dt))
        _check_window(np.zeros((self.window_samples, 3)), c.dt, c)  # rejects a too-short window
        self.events: list[WindowEvent] = []
        self.bind(batch_size)

    def bind(self, batch_size: int) -> None:
        """Allocate ``batch_size`` streams (all reset)."""
        if not (isinstance(batch_size, int | np.integer) and batch_size >= 1):
            raise ValueError(f"batch_size={batch_size!r} is invalid: an integer >= 1")
        # a ring buffer of the last window of samples; every row is written at ``_head``
        self._buffer = np.full((batch_size, self.window_samples, 3), np.nan)
        self._head = 0
        self.samples = np.zeros(batch_size, dtype=np.int64)
        self.model_update = np.ones(batch_size, dtype=bool)
        self.omega = np.tile(np.array(self.config.omega_initial), (batch_size, 1))
        self.theta0 = np.full((batch_size, 3), np.nan)
        #: last window's verdict: 1 accepted, 0 rejected, -1 none yet
        self.last_accepted = np.full(batch_size, -1, dtype=np.int8)
        self.updated = np.zeros(batch_size, dtype=bool)
        self._filled = np.zeros(batch_size, dtype=np.int64)
        self._since_check = np.zeros(batch_size, dtype=np.int64)
        self._firing = np.zeros(batch_size, dtype=np.int64)

    @property
    def batch_size(self) -> int:
        return self.model_update.size

    @property
    def time(self) -> FloatArray:
        """Time since each row's reset, s."""
        return self.samples * self.config.dt

    def reset(self, idx: ArrayLike | None = None) -> None:
        """Restart rows ``idx`` (all if None): flag set, frequencies back to the initial guess."""
        rows = _rows(idx, self.batch_size)
        self._buffer[rows] = np.nan
        self.samples[rows], self._filled[rows], self._since_check[rows] = 0, 0, 0
        self._firing[rows] = 0
        self.model_update[rows] = True
        self.omega[rows] = self.config.omega_initial
        self.theta0[rows] = np.nan
        self.last_accepted[rows] = -1
        self.updated[rows] = False

    def push(self, y: ArrayLike, mask: ArrayLike | None = None) -> NDArray[np.bool_]:
        """Add one sample per row: measured ``north, east, psi`` ``(N, 3)`` (m, m, rad); masked
        or non-finite channels count as missing. Runs the windows and checks that are due.

        :return: ``(N,)`` rows whose :attr:`omega` was just updated (an accepted window).
        """
        N = self.batch_size
        y = np.array(as_batch("y", y, N, 3), dtype=float)
        if mask is not None:
            y[~as_batch("mask", mask, N, 3).astype(bool)] = np.nan
        y[~np.isfinite(y)] = np.nan
        self._buffer[:, self._head] = y
        self._head = (self._head + 1) % self.window_samples
        self.samples += 1
        self._filled = np.minimum(self._filled + 1, self.window_samples)
        self._since_check += 1
        self.updated = np.zeros(N, dtype=bool)
        due = self.model_update & (self._filled >= self.window_samples)
        if due.any():
            self._estimate(np.flatnonzero(due))
        check = ~self.model_update & (self._since_check >= self.check_samples) & \
            (self._filled >= self.monitor_samples)
        if check.any():
            self._monitor(np.flatnonzero(check))
        return self.updated

    def _window(self, rows: NDArray[np.intp], samples: int) -> tuple[FloatArray, NDArray]:
        """The last ``samples`` of ``rows`` as ``(T, R, 3)`` with short gaps interpolated, and
        which rows had too many gaps to use."""
        order = (self._head - samples + np.arange(samples)) % self.window_samples
        data = self._buffer[rows[:, None], order[None]].transpose(1, 0, 2)
        unusable = np.zeros(rows.size, dtype=bool)
        t = np.arange(samples)
        for r in range(rows.size):
            for c in range(3):
                gap = ~np.isfinite(data[:, r, c])
                if gap.mean() > _MAX_MISSING:
                    unusable[r] = True
                elif gap.any():
                    data[gap, r, c] = np.interp(t[gap], t[~gap], data[~gap, r, c])
        return data, unusable

    def _estimate(self, rows: NDArray[np.intp]) -> None:
        data, unusable = self._window(rows, self.window_samples)
        self._filled[rows] = 0  # accepted or not, the next window starts afresh
        good = rows[~unusable]
        for r in rows[unusable]:
            self.last_accepted[r] = 0
            self.events.append(WindowEvent(int(r), float(self.time[r]), "rejected",
                                           np.full(3, np.nan), "too many missing samples"))
        if not good.size:
            return
        est = estimate_window(data[:, ~unusable], self.config.dt, self.config)
        for j, r in enumerate(good):
            ok = bool(est.accepted[j])
            self.last_accepted[r] = int(ok)
            self.theta0[r] = est.theta0[j]
            event = _row_estimate(est, j)
            kind: Literal["accepted", "rejected"] = "accepted" if ok else "rejected"
            self.events.append(WindowEvent(int(r), float(self.time[r]), kind,
                                           est.omega[j].copy(), event))
            if ok:
                self.omega[r] = est.omega[j]
                self.model_update[r], self.updated[r] = False, True
                self._filled[r] = self.window_samples  # the accepted window seeds the monitor
                self._since_check[r], self._firing[r] = 0, 0

    def _monitor(self, rows: NDArray[np.intp]) -> None:
        data, unusable = self._window(rows, self.monitor_samples)
        self._since_check[rows] = 0
        rows, data = rows[~unusable], data[:, ~unusable]
        if not rows.size:
            return
        data[:, :, 2] = np.unwrap(data[:, :, 2], axis=0)
        peak = spectral_peak(data, self.config.dt, self.config.band, self.config.damping)
        seen = np.isfinite(peak.theta0) & (np.nan_to_num(peak.snr) >= self.config.min_snr)
        moved = seen & (np.abs(np.where(seen, peak.theta0, 0) - self.omega[rows])
                        > self.config.threshold)
        fired = moved.any(axis=1)
        self._firing[rows] = np.where(fired, self._firing[rows] + 1, 0)
        changed = rows[self._firing[rows] >= self.config.change_confirmations]
        for r in changed:
            j = int(np.flatnonzero(rows == r)[0])
            self.events.append(WindowEvent(int(r), float(self.time[r]), "sea_change",
                                           peak.theta0[j].copy(),
                                           f"spectral peak {np.round(peak.theta0[j], 3)} "
                                           f"vs model {np.round(self.omega[r], 3)} rad/s"))
        self.model_update[changed] = True
        self._filled[changed], self._firing[changed] = 0, 0
