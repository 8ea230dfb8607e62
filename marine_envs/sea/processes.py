"""Slow and random exogenous signals besides waves: current, wind, bias, events.

Every source follows the protocol of :class:`~marine_envs.sea.waves.WaveRealisation`, which the
simulator drives: ``bind(batch_size)``, ``reset(idx, rngs)`` at episode start (drawing only from
the boats' own generators, so a batch equals the same boats one by one) and ``step()`` returning
the next value of every boat, shape ``(batch, width)``. :class:`Stacked` puts sources side by side
so that together they feed all of a model's disturbance inputs.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..blocks import BLOCK, BlockSource
from ..compiled import jit
from .shaping import DisturbanceModel, StateBlock, channel_names, combine, linear_model_of, stack

FloatArray = NDArray[np.float64]


class DisturbanceSource(Protocol):
    """What the simulator needs of a disturbance source."""

    def bind(self, batch_size: int) -> None: ...

    def reset(self, idx: NDArray[np.intp], rngs: Sequence[np.random.Generator]) -> None: ...

    def step(self) -> FloatArray: ...


def _check_period(dt: float) -> None:
    if not (isinstance(dt, int | float) and math.isfinite(dt) and dt > 0):
        raise ValueError(f"dt={dt!r} is invalid: the period the disturbances are held, > 0 s")


def _channels(name: str, value: ArrayLike, width: int | None = None) -> FloatArray:
    arr = np.atleast_1d(np.asarray(value, dtype=float))
    if arr.ndim != 1 or (width is not None and arr.size not in (1, width)):
        raise ValueError(f"{name}={np.asarray(value).tolist()!r} is invalid: one value per "
                         f"channel ({width} channels)")
    return np.broadcast_to(arr, (width or arr.size,)).copy()


class GaussMarkov(BlockSource):
    """First-order Gauss-Markov processes, one per channel: ``x_dot = -(x - mean)/T + noise``.

    Sampled exactly at the control period, so ``x_{k+1} = mean + a (x_k - mean) + std sqrt(1-a^2)
    n_k`` with ``a = exp(-dt/T)``, and each episode starts in the stationary distribution
    ``N(mean, std^2)``. ``T = 0`` gives white noise held over each step (std ``std``);
    ``T = inf`` a constant drawn at the start of each episode.

    :param mean: mean per channel (channel units).
    :param std: stationary standard deviation per channel (>= 0).
    :param time_constant: correlation time T per channel, s (>= 0, may be inf).
    :param dt: sampling period, s.
    """

    def __init__(self, mean: ArrayLike, std: ArrayLike, time_constant: ArrayLike,
                 dt: float) -> None:
        self.mean = _channels("mean", mean)
        width = self.mean.size
        self.std = _channels("std", std, width)
        tau = _channels("time_constant", time_constant, width)
        if not np.all(np.isfinite(self.std) & (self.std >= 0)):
            raise ValueError(f"std={self.std.tolist()} is invalid: must be finite and >= 0")
        if not np.all(tau >= 0):
            raise ValueError(f"time_constant={tau.tolist()} is invalid: must be >= 0 s")
        if not (math.isfinite(dt) and dt > 0):
            raise ValueError(f"dt={dt!r} is invalid: must be > 0 s")
        with np.errstate(divide="ignore"):
            self.a = np.exp(-dt / tau)
        self.gain = self.std * np.sqrt(1 - self.a**2)
        self._decay = self.a ** np.arange(BLOCK)[:, None]  # a**0 = 1 also for white noise
        super().__init__(width)

    def bind_state(self, batch_size: int) -> None:
        self._rngs: list[np.random.Generator] = [np.random.default_rng(0)] * batch_size
        self._last = np.zeros((batch_size, self.width))
        self._start = np.ones(batch_size, dtype=bool)

    def start(self, idx: NDArray[np.intp], rngs: Sequence[np.random.Generator]) -> None:
        for i, rng in zip(idx, rngs, strict=True):
            self._rngs[i] = rng
        self._start[idx] = True

    def blocks(self, idx: NDArray[np.intp]) -> FloatArray:
        block = np.empty((idx.size, BLOCK, self.width))
        for noise, i in zip(block, idx, strict=True):  # into place: no copy per boat
            self._rngs[i].standard_normal(out=noise)
        _filter_block(block, idx, self._start, self._last, self.std, self.gain, self.a,
                      self._decay, self.mean)
        return block

    def linear_model(self, dt: float, names: Sequence[str] | None = None) -> DisturbanceModel:
        """The exact AR(1) sampling per channel, ``xi_{k+1} = a xi_k + w_k`` with ``Var w =
        std^2 (1 - a^2)`` and a stationary start; white channels (``T = 0``) are white noise,
        constant ones (``std = 0``) their mean. The process is sampled at the period it was
        made with (``a``), which ``dt`` (s, the control period) is taken to be.

        :param names: the channels' names (default ``d0, d1, ...``).
        """
        _check_period(dt)
        names = channel_names(names, self.width)
        states: list[StateBlock] = []
        white = np.zeros(len(names))
        for c, name in enumerate(names):
            a, std = float(self.a[c]), float(self.std[c])
            if std == 0.0:
                continue  # a constant: its mean
            if a == 0.0:
                white[c] = std**2  # no memory: process noise
                continue
            states.append(((name,), np.array([[a]]), c, np.array([[self.gain[c] ** 2]]),
                           np.array([[std**2]])))
        return combine(states, len(names), self.mean, np.diag(white))


@jit
def _filter_block(noise, idx, start, last, std, gain, a, decay, mean):
    """Turn boats ``idx``'s standard normal numbers ``noise`` (boats x steps x channels) into
    their next block of :class:`GaussMarkov` values, in place: the exact AR(1) sampling
    ``y_t = gain n_t + a y_{t-1}`` (what ``scipy.signal.lfilter([gain], [1, -a])`` computes)
    continuing each boat's ``last`` value, or, where ``start``, from the stationary
    distribution (``std`` times the first number, decaying as ``decay = a**t``); then the
    ``mean``. Updates ``last`` and clears ``start`` of those boats. One compiled pass: a boat
    refilled alone would otherwise pay a dozen numpy calls."""
    boats, steps, width = noise.shape
    for r in range(boats):
        b = idx[r]
        for c in range(width):
            if start[b]:  # the first number sets the stationary start; the recursion is 0
                first, y, n0 = std[c] * noise[r, 0, c], a[c] * 0.0, 0.0
            else:
                first, y, n0 = 0.0, a[c] * last[b, c], noise[r, 0, c]
            value = 0.0
            for t in range(steps):
                y = gain[c] * (n0 if t == 0 else noise[r, t, c]) + y
                value = first * decay[t, c] + y
                noise[r, t, c] = value + mean[c]
                y = a[c] * y
            last[b, c] = value
        start[b] = False


class StepEvent(BlockSource):
    """Channels that jump from ``before`` to ``after`` once per episode, at a given time or at a
    time drawn uniformly from ``window`` (e.g. the ROV's morph command).

    :param before, after: values per channel.
    :param time: switching time, s; or None to draw it from ``window``.
    :param window: ``(earliest, latest)`` switching time, s, when ``time`` is None.
    :param dt: sampling period, s.
    """

    def __init__(self, before: ArrayLike, after: ArrayLike, *, dt: float,
                 time: float | None = None,
                 window: tuple[float, float] | None = None) -> None:
        self.before = _channels("before", before)
        self.after = _channels("after", after, self.before.size)
        self.width = self.before.size
        if (time is None) == (window is None):
            raise ValueError("give exactly one of time=... (s) and window=(earliest, latest)")
        if time is not None and not (math.isfinite(time) and time >= 0):
            raise ValueError(f"time={time!r} is invalid: a switching time >= 0 s")
        if window is not None and not (len(window) == 2 and 0 <= window[0] <= window[1]
                                       and math.isfinite(window[1])):
            raise ValueError(f"window={window!r} is invalid: (earliest, latest) with "
                             "0 <= earliest <= latest s")
        self.time, self.window, self.dt = time, window, dt
        super().__init__(self.width)

    def bind_state(self, batch_size: int) -> None:
        self._switch_step = np.zeros(batch_size, dtype=np.int64)
        self._step = np.zeros(batch_size, dtype=np.int64)  # at the start of the next block

    def start(self, idx: NDArray[np.intp], rngs: Sequence[np.random.Generator]) -> None:
        for i, rng in zip(idx, rngs, strict=True):
            t = self.time if self.window is None else rng.uniform(*self.window)
            self._switch_step[i] = math.ceil(t / self.dt - 1e-9)
        self._step[idx] = 0

    def blocks(self, idx: NDArray[np.intp]) -> FloatArray:
        steps = self._step[idx, None] + np.arange(BLOCK)  # (boats, BLOCK)
        self._step[idx] += BLOCK
        switched = steps >= self._switch_step[idx, None]
        return np.where(switched[:, :, None], self.after, self.before)

    def switch_time(self) -> FloatArray:
        """Each boat's switching time this episode, s (on the step grid)."""
        return self._switch_step * self.dt

    def linear_model(self, dt: float, names: Sequence[str] | None = None) -> DisturbanceModel:
        """A random walk per channel that jumps: the jump's square spread over the steps of
        ``dt`` (s) in the window it falls in (or up to its fixed time); the start is known.

        :param names: the channels' names (default ``d0, d1, ...``).
        """
        _check_period(dt)
        names = channel_names(names, self.width)
        span = self.window[1] - self.window[0] if self.window is not None else self.time
        steps = max(float(span) / dt, 1.0)
        states: list[StateBlock] = []
        for c, name in enumerate(names):
            jump = float(self.after[c] - self.before[c])
            if jump != 0.0:
                states.append(((name,), np.array([[1.0]]), c, np.array([[jump**2 / steps]]),
                               np.zeros((1, 1))))
        return combine(states, len(names), self.before, np.zeros((len(names), len(names))))


class Stacked(BlockSource):
    """Several sources side by side: their columns concatenated in the order given, in one
    stream (each source's own stream stays unbound)."""

    def __init__(self, *sources: BlockSource) -> None:
        if not sources:
            raise ValueError("Stacked needs at least one source")
        self.sources = sources
        super().__init__(sum(source.width for source in sources))

    def bind_state(self, batch_size: int) -> None:
        for source in self.sources:
            source.bind_state(batch_size)

    def start(self, idx: NDArray[np.intp], rngs: Sequence[np.random.Generator]) -> None:
        for source in self.sources:
            source.start(idx, rngs)

    def blocks(self, idx: NDArray[np.intp]) -> FloatArray:
        return np.concatenate([source.blocks(idx) for source in self.sources], axis=2)

    def linear_model(self, dt: float, names: Sequence[str] | None = None) -> DisturbanceModel:
        """The sources' models side by side (a source without one: white noise of its sampled
        covariance, :func:`~marine_envs.sea.shaping.linear_model_of`).

        :param dt: the period the disturbances are held, s.
        :param names: the channels' names (default ``d0, d1, ...``).
        """
        _check_period(dt)
        names = channel_names(names, self.width)
        parts, start = [], 0
        for source in self.sources:
            parts.append(linear_model_of(source, dt, names[start:start + source.width]))
            start += source.width
        return stack(parts)
