"""Linear (shaping-filter) models of disturbance sources: what a Kalman filter carries as states.

Each source describes its own discrete model (``linear_model(dt)``:
:meth:`~marine_envs.sea.processes.GaussMarkov.linear_model`,
:meth:`~marine_envs.sea.processes.StepEvent.linear_model`,
:meth:`~marine_envs.sea.waves.WaveRealisation.linear_model`, side by side
:meth:`~marine_envs.sea.processes.Stacked.linear_model`); this module holds the model's form,
:class:`DisturbanceModel`, and the pieces they are built from. :func:`linear_model_of` takes a
source without a model of its own as white noise of its sampled covariance.
"""

from __future__ import annotations

import copy
import dataclasses
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
#: Steps of a sea sampled for each wave channel's autocovariance (several episodes' worth, from
#: fixed seeds: the same model every time).
WAVE_SAMPLE_STEPS, WAVE_SAMPLE_SEEDS = 8192, (0, 1, 2, 3)


@dataclasses.dataclass(frozen=True)
class DisturbanceModel:
    """The discrete model of disturbances ``d_k`` (held over step k)::

        xi_{k+1} = F xi_k + w_k,   w_k ~ N(0, Q)
        d_k      = mean + C xi_k + v_k,   v_k ~ N(0, white)   (the channels without memory)

    :ivar names: a name per state of ``xi`` (the disturbance channel's, ``_prev`` for the lag of
        a wave channel's AR(2)).
    :ivar P0: the covariance of ``xi`` at an episode's start (its stationary one, or 0 where
        the start is known).
    :ivar wave_peaks: ``{channel: (peak frequency rad/s, damping ratio)}`` of each wave channel's
        shaping filter (the AR(2)'s poles as a continuous second-order system).
    """

    F: FloatArray
    C: FloatArray
    Q: FloatArray
    P0: FloatArray
    mean: FloatArray
    white: FloatArray
    names: tuple[str, ...]
    wave_peaks: dict[str, tuple[float, float]]

    @property
    def size(self) -> int:
        """Number of disturbance-model states."""
        return len(self.names)

    def stationary_covariance(self) -> FloatArray:
        """The stationary covariance of ``d_k - mean`` (``C P C' + white`` with ``P = F P F' +
        Q``), channel units squared; inf on a channel driven by a random walk."""
        import scipy.linalg  # (here: importing marine_envs need not load it)

        if self.size == 0:
            return self.white.copy()
        if np.any(np.abs(np.linalg.eigvals(self.F)) >= 1.0):
            P = np.full(self.F.shape, np.inf)
        else:
            P = scipy.linalg.solve_discrete_lyapunov(self.F, self.Q)
        return self.C @ P @ self.C.T + self.white


# a channel's block of states: (their names, F block, the channel's index, Q block, P0 block)
StateBlock = tuple[tuple[str, ...], FloatArray, int, FloatArray, FloatArray]


def channel_names(names: Sequence[str] | None, width: int) -> tuple[str, ...]:
    """``names`` checked against a source's ``width``, or ``d0, d1, ...``."""
    if names is None:
        return tuple(f"d{c}" for c in range(width))
    if len(names) != width:
        raise ValueError(f"names={list(names)} is invalid: one name per channel ({width})")
    return tuple(names)


def combine(states: list[StateBlock], n_channels: int, mean: Any, white: FloatArray
            ) -> DisturbanceModel:
    """The model of ``n_channels`` channels from blocks of states, one per channel with memory
    (the channel is the first state of its block); the other channels are their ``mean`` plus
    ``white`` noise."""
    import scipy.linalg  # (here: importing marine_envs need not load it)

    names = tuple(name for state in states for name in state[0])
    C = np.zeros((n_channels, len(names)))
    column = 0
    for state_names, _, channel, _, _ in states:
        C[channel, column] = 1.0  # the channel is the first state of its block
        column += len(state_names)
    F = scipy.linalg.block_diag(np.zeros((0, 0)), *(state[1] for state in states))
    Q = scipy.linalg.block_diag(np.zeros((0, 0)), *(state[3] for state in states))
    P0 = scipy.linalg.block_diag(np.zeros((0, 0)), *(state[4] for state in states))
    return DisturbanceModel(F, C, Q, P0, np.asarray(mean, dtype=float).copy(), white, names, {})


def stack(parts: list[DisturbanceModel]) -> DisturbanceModel:
    """Models of consecutive channel groups side by side."""
    import scipy.linalg  # (here: importing marine_envs need not load it)

    def diag(attr: str) -> FloatArray:
        return scipy.linalg.block_diag(np.zeros((0, 0)), *(getattr(p, attr) for p in parts))

    peaks = {k: v for p in parts for k, v in p.wave_peaks.items()}
    return DisturbanceModel(diag("F"), diag("C"), diag("Q"), diag("P0"),
                            np.concatenate([p.mean for p in parts]), diag("white"),
                            tuple(n for p in parts for n in p.names), peaks)


def no_disturbance(names: Sequence[str]) -> DisturbanceModel:
    """The model of channels that stay 0."""
    n = len(names)
    return combine([], n, np.zeros(n), np.zeros((n, n)))


def linear_model_of(source: Any, dt: float, names: Sequence[str] | None = None
                    ) -> DisturbanceModel:
    """``source.linear_model(dt, names)``; a source without one is white noise of the
    covariance of its values over a run of a fixed seed (held over each step)."""
    if hasattr(source, "linear_model"):
        return source.linear_model(dt, names)
    samples = sample_steps(source, 2000)
    names = channel_names(names, samples.shape[1])
    return combine([], len(names), samples.mean(axis=0),
                   np.atleast_2d(np.cov(samples, rowvar=False)))


def sample_steps(source: Any, steps: int, seed: int = 0) -> FloatArray:
    """One boat's values of a copy of ``source`` over ``steps`` steps (steps x width), from
    ``np.random.default_rng(seed)``, through the source protocol (bind, reset, step)."""
    copy_ = copy.deepcopy(source)
    copy_.bind(1)
    copy_.reset(np.array([0]), [np.random.default_rng(seed)])
    return np.concatenate([copy_.step() for _ in range(steps)])


def sample_blocks(source: Any, steps: int = 2000, seed: int = 0) -> FloatArray:
    """:func:`sample_steps` of a block source (:class:`~marine_envs.blocks.BlockSource`), a
    block at a time (the rows its steps would hand out)."""
    copy_ = copy.deepcopy(source)
    copy_.bind(1)
    boat = np.array([0])
    copy_.reset(boat, [np.random.default_rng(seed)])
    chunks = [copy_.stream.blocks[0].copy()]
    while sum(map(len, chunks)) < steps:
        chunks.append(copy_.blocks(boat)[0])
    return np.concatenate(chunks)[:steps]


def autocovariance(x: FloatArray, lags: int) -> FloatArray:
    """The biased sample autocovariance of ``x`` at lags ``0 .. lags - 1``."""
    x = x - x.mean()
    return np.array([x[:x.size - k] @ x[k:] / x.size for k in range(lags)])


def second_order(phi1: float, phi2: float, dt: float) -> tuple[float, float]:
    """Peak frequency (rad/s) and damping ratio of the AR(2)'s poles ``z = exp(s dt)``."""
    s = np.log(np.roots([1.0, -phi1, -phi2]).astype(complex)) / dt
    wn = float(np.abs(s).max())
    return wn, float(-s.real.max() / wn) if wn > 0 else 1.0


__all__ = ["WAVE_SAMPLE_SEEDS", "WAVE_SAMPLE_STEPS", "DisturbanceModel", "StateBlock",
           "autocovariance", "channel_names", "combine", "linear_model_of", "no_disturbance",
           "sample_blocks", "sample_steps", "second_order", "stack"]
