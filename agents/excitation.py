"""Open-loop excitation signals for identification runs and recordings.

Each signal is a policy with SB3's ``predict`` signature that ignores the observation and
returns actions in [-1, 1] as a function of the step count, about a centre (usually the action of
the vehicle's nominal input, so that the excitation perturbs its trim); signals that are random
draw from their own seeded generator.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from typing import Any

import numpy as np
from numpy.typing import NDArray


class Excitation(ABC):
    """Base class: a function of the step index ``k`` (time ``k * dt``)."""

    def __init__(self, n_inputs: int, dt: float) -> None:
        self.n_inputs, self.dt, self.k = n_inputs, dt, 0
        self.centre = np.zeros(n_inputs)

    @abstractmethod
    def value(self, t: float) -> NDArray[np.float64]:
        """Actions (normalised) at time ``t``, s."""

    def predict(self, observation: Any = None, state: Any = None, episode_start: Any = None,
                deterministic: bool = True) -> tuple[NDArray[np.float32], None]:
        action = np.clip(self.centre + self.value(self.k * self.dt), -1.0, 1.0)
        action = action.astype(np.float32)
        self.k += 1
        return action, None


class Zero(Excitation):
    """No excitation: the centre action (the nominal input) throughout."""

    def value(self, t: float) -> NDArray[np.float64]:
        return np.zeros(self.n_inputs)


class Sine(Excitation):
    """``amplitude * sin(2 pi t / period)`` on every input (normalised units, period in s)."""

    def __init__(self, n_inputs: int, dt: float, amplitude: float = 0.3,
                 period: float = 20.0) -> None:
        super().__init__(n_inputs, dt)
        if not (0 < amplitude <= 1 and period > 0):
            raise ValueError(f"sine needs 0 < amplitude <= 1 and period > 0 s "
                             f"(got {amplitude}, {period})")
        self.amplitude, self.period = amplitude, period

    def value(self, t: float) -> NDArray[np.float64]:
        return np.full(self.n_inputs, self.amplitude * math.sin(2 * math.pi * t / self.period))


class RandomSteps(Excitation):
    """Piecewise-constant levels held for ``hold`` seconds: uniform in [-amplitude, amplitude],
    or +-amplitude only when ``binary`` (a pseudo-random binary sequence, PRBS)."""

    def __init__(self, n_inputs: int, dt: float, amplitude: float = 0.3, hold: float = 5.0,
                 binary: bool = False, seed: int | None = None) -> None:
        super().__init__(n_inputs, dt)
        if not (0 < amplitude <= 1 and hold > 0):
            raise ValueError(f"random steps need 0 < amplitude <= 1 and hold > 0 s "
                             f"(got {amplitude}, {hold})")
        self.amplitude, self.hold, self.binary = amplitude, hold, binary
        self.rng = np.random.default_rng(seed)
        self._level, self._until = np.zeros(n_inputs), -1.0

    def value(self, t: float) -> NDArray[np.float64]:
        if t >= self._until:
            draw = self.rng.uniform(-1.0, 1.0, self.n_inputs)
            self._level = self.amplitude * (np.sign(draw) if self.binary else draw)
            self._until = t + self.hold
        return self._level


class Dithered:
    """A feedback policy plus an excitation on its actions: the closed-loop identification
    experiment (the loop holds the vehicle near its operating point, the dither keeps every
    input moving so that a model can be judged on the record)."""

    def __init__(self, policy: Any, dither: Excitation) -> None:
        self.policy, self.dither = policy, dither

    def predict(self, observation: Any, state: Any = None, episode_start: Any = None,
                deterministic: bool = True) -> tuple[NDArray[np.float32], None]:
        action, _ = self.policy.predict(observation, state, episode_start, deterministic)
        offset, _ = self.dither.predict()
        return np.clip(action + offset, -1.0, 1.0).astype(np.float32), None


SIGNALS = {"zero": Zero, "sine": Sine, "random": RandomSteps,
           "prbs": lambda n, dt, **kw: RandomSteps(n, dt, binary=True, **kw)}
