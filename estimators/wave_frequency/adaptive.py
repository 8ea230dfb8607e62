"""The wave filter joined to the online estimator as one estimator, and the Gymnasium wrapper that
puts it on ``DPVessel-v0``."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import ArrayLike

from ..base import Estimator
from ..wrappers import EstimatorWrapper
from .config import CHANNELS, FloatArray, WaveFrequencyConfig, _rows
from .online import WaveFrequencyEstimator
from .wave_filter import WaveFilter


class AdaptiveWaveFilter(Estimator):
    """:class:`WaveFilter` whose WF model follows :class:`WaveFrequencyEstimator`: every
    measurement also feeds the state machine, and an accepted window's frequencies go to the
    filter (the DP wave-frequency patent's "model update"). Works in
    :class:`~estimators.wrappers.EstimatorWrapper` and
    :class:`~estimators.wrappers.VectorEstimatorWrapper`.

    :param wave_filter: the DP observer (its initial ``w0`` should be the config's
        ``omega_initial``).
    :param estimator: the state machine (default: the DP wave-frequency patent's settings with
        the filter's ``dt``).
    """

    measurement_names = CHANNELS

    def __init__(self, wave_filter: WaveFilter, estimator: WaveFrequencyEstimator | None = None
                 ) -> None:
        self.wave_filter = wave_filter
        self.estimator = estimator or WaveFrequencyEstimator(
            WaveFrequencyConfig(dt=wave_filter.dt, omega_initial=tuple(wave_filter.w0_initial)))
        if not math.isclose(self.estimator.config.dt, wave_filter.dt):
            raise ValueError(f"the estimator's dt {self.estimator.config.dt} s differs from the "
                             f"wave filter's {wave_filter.dt} s")
        self.state_names, self.dt = wave_filter.state_names, wave_filter.dt
        self.bind(wave_filter.batch_size)

    @classmethod
    def for_env(cls, env: Any, config: WaveFrequencyConfig | None = None,
                **kwargs: Any) -> AdaptiveWaveFilter:
        """:meth:`for_system` of a ``DPVessel-v0`` environment (possibly wrapped)."""
        return cls.for_system(env.unwrapped.system, config, **kwargs)

    @classmethod
    def for_system(cls, system: Any, config: WaveFrequencyConfig | None = None,
                   **kwargs: Any) -> AdaptiveWaveFilter:
        """For the DP vessel's system (``env.unwrapped.system``); ``kwargs`` go to
        :meth:`WaveFilter.for_system`."""
        config = dataclasses.replace(config or WaveFrequencyConfig(), dt=system.dt)
        wave_filter = WaveFilter.for_system(system, w0=config.omega_initial, **kwargs)
        return cls(wave_filter, WaveFrequencyEstimator(config))

    # the filter's arrays are the estimate
    x = property(lambda self: self.wave_filter.x)
    P = property(lambda self: self.wave_filter.P)
    innovation = property(lambda self: self.wave_filter.innovation)
    diverged = property(lambda self: self.wave_filter.diverged)

    def bind(self, batch_size: int) -> None:
        self.wave_filter.bind(batch_size)
        self.estimator.bind(batch_size)
        self._fresh = np.ones(batch_size, dtype=bool)

    def reset(self, x0: ArrayLike | None = None, P0: ArrayLike | None = None,
              idx: ArrayLike | None = None) -> None:
        rows = _rows(idx, self.wave_filter.batch_size)
        self.wave_filter.reset(x0, P0, rows)
        self.estimator.reset(rows)
        self._fresh[rows] = True

    def predict(self, u: ArrayLike, dt: float | None = None) -> FloatArray:
        self._fresh[:] = True
        return self.wave_filter.predict(u, dt)

    def update(self, y: ArrayLike, mask: ArrayLike | None = None) -> tuple[FloatArray, FloatArray]:
        out = self.wave_filter.update(y, mask)
        # a measurement repeated without a prediction (a restart after divergence) is one sample
        if self._fresh.all():
            updated = self.estimator.push(y, mask)
            rows = np.flatnonzero(updated)
            if rows.size:
                self.wave_filter.set_wave_frequencies(self.estimator.omega[rows], rows)
        self._fresh[:] = False
        return out


class WaveFrequencyWrapper(EstimatorWrapper):
    """``DPVessel-v0`` seen through the adaptive wave filter: the observation is the filter's
    15-state estimate (LF position and heading first, then velocities, bias and WF states; what
    :meth:`agents.lqr.LQRPolicy.for_env` reads with ``observed="auto"``), and the WF model is
    re-estimated online (the DP wave-frequency patent).

    ``info`` gets, besides :class:`~estimators.wrappers.EstimatorWrapper`'s keys:

    * ``wave_frequencies`` ``(3,)``: the frequencies the filter uses now, rad/s;
    * ``wave_model_update``: the patent's flag (a window is being collected for estimation);
    * ``wave_window_accepted``: the last window's verdict (None before the first);
    * ``wave_frequencies_updated``: this step changed the filter's frequencies;
    * ``wave_theta0`` ``(3,)``: the last window's spectral pre-estimate, rad/s (None before the
      first; NaN where a window had no peak).

    :param env: a ``DPVessel-v0`` environment.
    :param config: the pipeline's settings (``dt`` is taken from the environment).
    :param kwargs: to :class:`~estimators.wrappers.EstimatorWrapper` (``x0``, ``P0``, ...).
    """

    def __init__(self, env: gym.Env, config: WaveFrequencyConfig | None = None,
                 **kwargs: Any) -> None:
        # recorded first, so that env.spec rebuilds this wrapper, not its base
        gym.utils.RecordConstructorArgs.__init__(self, config=config, **kwargs)
        self.adaptive = AdaptiveWaveFilter.for_env(env, config)
        super().__init__(env, self.adaptive, **kwargs)

    def _correct(self, obs: np.ndarray, info: dict[str, Any]):
        estimate, info = super()._correct(obs, info)
        machine = self.adaptive.estimator
        verdict = int(machine.last_accepted[0])
        info = {**info, "wave_frequencies": self.adaptive.wave_filter.wave_frequencies[0].copy(),
                "wave_model_update": bool(machine.model_update[0]),
                "wave_window_accepted": None if verdict < 0 else bool(verdict),
                "wave_frequencies_updated": bool(machine.updated[0]),
                "wave_theta0": None if verdict < 0 else machine.theta0[0].copy()}
        return estimate, info
