"""The sea estimated online: a bank of disturbance-model Kalman filters, one per candidate sea.

:func:`~estimators.disturbance.disturbance_filter` takes each wave channel's shaping filter from
the env's own sea. When the sea is not known, :func:`sea_bank_filter` builds that filter for
each sea of a grid of peak periods and heights (the vehicle, its wave coupling and its sensors
are the env's; only the sea differs) and runs them side by side as a
:class:`MultipleModelFilter`: each filter's weight follows the likelihood of its innovations,
the estimate is the mixture's mean, and the weighted sea (:attr:`MultipleModelFilter.parameters`)
is the estimate of the sea (peak period, height, and each wave channel's peak frequency). This is
the multiple-model adaptive estimator (Magill 1965) as Hassani, Sorensen, Pascoal and Aguiar
(2012) applied it to the wave filtering of DP vessels, where the sea state is unknown and
changes.

The grid is the vehicle's, not the episode's: the peak periods and heights of the env's
registered default sea (its design sea) times :data:`PERIOD_FACTORS` and :data:`HEIGHT_FACTORS`,
so the bank knows the vehicle's operating envelope but never the sea it is run in.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import ArrayLike, NDArray

from marine_envs.sea.spectra import PM_WP_COEF
from marine_envs.sea.waves import WaveRealisation

from .base import Estimator
from .disturbance import augmented_system
from .kalman import KalmanFilter

FloatArray = NDArray[np.float64]
#: Candidate peak periods and significant heights, as factors of the design sea's: periods from
#: half to twice in steps of 19 % (a sea between two is within 9 % of one), heights 0.5-2.
PERIOD_FACTORS = tuple(float(f) for f in np.geomspace(0.5, 2.0, 9))
HEIGHT_FACTORS = (0.5, 1.0, 2.0)
#: The memory of the weights, s: each filter's log-likelihood is summed with a forgetting factor
#: ``exp(-dt / MEMORY)``. One step says little about the sea (the weights of a product of
#: likelihoods, floored to stay adaptive, swung between peak periods 4 and 9 s every few seconds
#: on the hydrofoil); a sum over minutes does, and forgetting lets a changed sea take over.
MEMORY = 120.0
#: The env's keyword arguments that are not the vehicle's (gym.make's own).
_MAKE_KEYS = ("max_episode_steps", "num_envs", "vectorization_mode", "render_mode")


class MultipleModelFilter(Estimator):
    """A bank of ``K`` Kalman filters with the same states that differ in their model, for a
    batch of ``N`` boats: the multiple-model adaptive estimator.

    Each filter's score is the log-likelihood of its innovations, ``-(e_k' S_k^-1 e_k +
    log |S_k|) / 2`` per update, summed with the forgetting factor ``exp(-dt / memory)``; the
    weights are the scores' softmax. The estimate ``x`` is the weighted mean of the filters',
    ``P`` the mixture's covariance (the filters' spread included).

    :param filters: the bank, each bound to the same batch size by this class.
    :param labels: ``{name: (K,) values}``: what each filter assumes (e.g. the sea's peak
        period, s); :attr:`parameters` gives their weighted means per boat.
    :param memory: time constant of the scores' forgetting, s.
    :param batch_size: number of boats ``N``.
    """

    def __init__(self, filters: Sequence[KalmanFilter], labels: Mapping[str, ArrayLike], *,
                 memory: float = MEMORY, batch_size: int = 1) -> None:
        if not filters:
            raise ValueError("a bank needs at least one filter")
        first = filters[0]
        for f in filters[1:]:
            if (f.state_names, f.measurement_names) != (first.state_names,
                                                        first.measurement_names):
                raise ValueError("the bank's filters must share their states and measurements")
        self.labels = {k: np.asarray(v, dtype=float) for k, v in labels.items()}
        if any(v.shape != (len(filters),) for v in self.labels.values()):
            raise ValueError(f"labels must hold one value per filter ({len(filters)})")
        if not (np.isfinite(memory) and memory > 0):
            raise ValueError(f"memory={memory!r} is invalid: a time constant > 0 s")
        self.filters = list(filters)
        self.memory = float(memory)
        self.state_names, self.measurement_names = first.state_names, first.measurement_names
        self.dt = first.dt
        self.bind(batch_size)

    @property
    def P(self) -> FloatArray:
        """Covariance of the mixture, ``(N, n, n)``: the weighted filters' covariances plus
        the spread of their estimates about the mean."""
        spread = self._stack_x() - self.x[:, None]
        P = np.stack([np.broadcast_to(f.P, (self.batch_size, *f.P.shape[1:]))
                      for f in self.filters], axis=1)
        return np.einsum("nk,nkij->nij", self.weights, P + spread[..., None] * spread[:, :, None])

    @property
    def parameters(self) -> dict[str, FloatArray]:
        """``{label: (N,)}``: each label's weighted mean per boat (the bank's estimate of what
        its filters differ in)."""
        return {name: self.weights @ values for name, values in self.labels.items()}

    def bind(self, batch_size: int) -> None:
        for f in self.filters:
            f.bind(batch_size)
        self.scores = np.zeros((batch_size, len(self.filters)))
        self._weigh()

    def reset(self, x0: ArrayLike | None = None, P0: ArrayLike | None = None,
              idx: ArrayLike | None = None) -> None:
        for f in self.filters:
            f.reset(x0, P0, idx)
        rows = slice(None) if idx is None else np.atleast_1d(np.asarray(idx))
        self.scores[rows] = 0.0
        self._weigh()

    def predict(self, u: ArrayLike, dt: float | None = None) -> FloatArray:
        for f in self.filters:
            f.predict(u, dt)
        self._mix()
        return self.x

    def update(self, y: ArrayLike, mask: ArrayLike | None = None) -> tuple[FloatArray, FloatArray]:
        for f in self.filters:
            f.update(y, mask)
        log_likelihood = np.stack([-0.5 * (f.nis + np.linalg.slogdet(f.innovation_cov)[1])
                                   for f in self.filters], axis=1)
        # a filter that diverged (NaN) scores -inf; a boat with no finite score keeps its scores
        log_likelihood = np.where(np.isfinite(log_likelihood), log_likelihood, -np.inf)
        scored = np.isfinite(log_likelihood).any(axis=1, keepdims=True)
        forget = np.exp(-self.dt / self.memory)
        scores = forget * self.scores + log_likelihood
        scores = np.maximum(scores - scores.max(axis=1, keepdims=True), -700.0)  # exp stays > 0
        self.scores = np.where(scored, scores, self.scores)
        self._weigh()
        return self.x, self.P

    def _stack_x(self) -> FloatArray:
        return np.stack([f.x for f in self.filters], axis=1)  # (N, K, n)

    def _weigh(self) -> None:
        """The weights from the scores (their softmax), then the mixture."""
        w = np.exp(self.scores - self.scores.max(axis=1, keepdims=True))
        self.weights = w / w.sum(axis=1, keepdims=True)
        self._mix()

    def _mix(self) -> None:
        """The bank's estimate, innovation and health from its filters' and the weights."""
        self.x = np.einsum("nk,nki->ni", self.weights, self._stack_x())
        self.innovation = np.einsum("nk,nki->ni", self.weights,
                                    np.stack([f.innovation for f in self.filters], axis=1))
        self.diverged = np.all([f.diverged for f in self.filters], axis=0)


def sea_bank_filter(env: Any, periods: Sequence[float] | None = None,
                    heights: Sequence[float] | None = None, **kwargs: Any
                    ) -> MultipleModelFilter:
    """A :class:`MultipleModelFilter` of disturbance-model Kalman filters
    (:func:`~estimators.disturbance.disturbance_filter`), one per sea of the grid ``periods`` x
    ``heights``, for an env made by ``gym.make`` (its vehicle, sensors and options; its sea is
    not read).

    :param periods, heights: candidate peak periods (s) and significant wave heights (m)
        (default: the design sea's, :func:`design_sea`, times :data:`PERIOD_FACTORS` and
        :data:`HEIGHT_FACTORS`).
    :param kwargs: passed to each filter (``batch_size``, ...).
    :return: the bank; its ``labels`` are ``tp`` (s), ``hs`` (m) and, per wave channel,
        ``<channel>_peak`` (the shaping filter's peak frequency, rad/s).
    :raises ValueError: the env has no wave channel, or was not made by ``gym.make``.
    """
    options, spec = vehicle_options(env), env.unwrapped.spec  # one env per candidate sea
    try:
        _sea(env.unwrapped.system)
    except ValueError:
        raise ValueError(f"{spec.id} has no wave-driven disturbance channel: its kf has no sea "
                         "to estimate") from None
    tp0, hs0 = design_sea(spec.id, options)
    periods = [f * tp0 for f in PERIOD_FACTORS] if periods is None else periods
    heights = [f * hs0 for f in HEIGHT_FACTORS] if heights is None else heights
    filters, labels = [], {"tp": [], "hs": []}
    for tp in periods:
        for hs in heights:
            system = augmented_system(gym.make(spec.id, **options, tp=float(tp), hs=float(hs)))
            filters.append(KalmanFilter(**system.filter_arguments(), **kwargs))
            labels["tp"].append(tp)
            labels["hs"].append(hs)
            for channel, (omega, _) in system.disturbances.wave_peaks.items():
                labels.setdefault(f"{channel}_peak", []).append(omega)
    return MultipleModelFilter(filters, labels, batch_size=kwargs.get("batch_size", 1))


def vehicle_options(env: Any) -> dict[str, Any]:
    """The keyword arguments ``env`` was made with (``gym.make``), but its sea's."""
    spec = env.unwrapped.spec
    if spec is None:
        raise ValueError("the env was not made by gym.make: its options are unknown (a bank "
                         "makes one env per candidate sea with the env's own options)")
    return {k: v for k, v in spec.kwargs.items() if k not in (*_MAKE_KEYS, "hs", "tp")}


def design_sea(env_id: str, options: Mapping[str, Any] | None = None) -> tuple[float, float]:
    """Peak period (s) and significant height (m) of the registered default sea of ``env_id``
    (made with ``options``): its highest height, and its period or, for the one-parameter
    Pierson-Moskowitz, the peak period that height implies."""
    sea = _sea(gym.make(env_id, **dict(options or {})).unwrapped.system)
    hs = sea.hs_range()[1]
    return (sea.tp if sea.tp is not None else 2 * np.pi * np.sqrt(hs) / PM_WP_COEF), hs


def _sea(system: Any) -> Any:
    """The sea state of the system's wave realisation (alone or in a stack of sources)."""
    sources = [system.disturbances]
    while sources:
        source = sources.pop()
        if isinstance(source, WaveRealisation):
            return source.sea
        sources.extend(getattr(source, "sources", ()))
    raise ValueError("the system has no wave realisation")


__all__ = ["HEIGHT_FACTORS", "MEMORY", "PERIOD_FACTORS", "MultipleModelFilter", "design_sea",
           "sea_bank_filter", "vehicle_options"]
