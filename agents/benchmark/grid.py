"""The benchmark grid's vocabulary: vehicles, sea states, sensor degradations, controllers, and
:class:`Grid`, the cells ``marine bench`` runs (all but the seed: a cell runs its seeds as one
batch)."""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from estimators.registry import ESTIMATORS, ORACLE, RAW

from ..policies import ALIASES, canonical, names

VEHICLES = {"usv": "marine_envs/USV-v0", "hydrofoil": "marine_envs/Hydrofoil-v0",
            "rov": "marine_envs/ROV-v0", "dp": "marine_envs/DPVessel-v0",
            "hovercraft": "marine_envs/Hovercraft-v0"}
#: Sea states (and the ROV's current, the hovercraft's wind) as environment arguments;
#: "moderate" is each environment's default.
SEAS: dict[str, dict[str, dict[str, Any]]] = {
    "calm": {"usv": {"hs": 1.0}, "hydrofoil": {"hs": 0.10},
             "rov": {"current": (0.05, 0.0, 0.0), "current_std": 0.02},
             "dp": {"params": {"sigma_eta": [0.5, 0.5, math.radians(1.0)],
                               "sigma_b": [2.5e4, 2.5e4, 5e5]}},
             "hovercraft": {"wind_speed": 2.0, "wind_gust": 0.5}},
    "moderate": {v: {} for v in VEHICLES},
    "rough": {"usv": {"hs": 3.5, "tp": 9.0}, "hydrofoil": {"hs": 0.30},
              "rov": {"current": (0.3, 0.0, 0.0), "current_std": 0.1},
              "dp": {"params": {"sigma_eta": [2.0, 2.0, math.radians(4.0)],
                                "sigma_b": [1e5, 1e5, 2e6]}},
              "hovercraft": {"wind_speed": 10.0, "wind_gust": 2.0}},
}
#: Sensor degradations: ``default`` or ``kind=level`` joined by ``+``. ``noise=k``: k times
#: each channel's default noise std; ``quant=k``: a quantization step of k default stds;
#: ``dropout=p``: each sample lost with probability p; ``delay=n``: n control periods late.
DEGRADATIONS = ("noise", "quant", "dropout", "delay")
SB3_ALGOS = ("ppo", "sac", "td3", "a2c")
#: The policies of :mod:`agents.policies` that act on a batch of boats, and the SB3 algorithms
#: the grid trains an agent of; and "sb3:DIR" for a saved agent.
CONTROLLERS = (*sorted(names(batched=True)), *SB3_ALGOS)
KEYS = ("vehicle", "estimator", "controller", "sea", "sensor")
TRAINING_SEED = 10_000  # agents never train on the evaluation seeds 0, 1, ...


@dataclasses.dataclass(frozen=True)
class Grid:
    """What ``marine bench`` runs.

    :param seeds: episodes per cell (seeds ``0 .. seeds - 1``).
    :param seconds: episode length, s (None: each environment's own).
    :param timesteps: training budget of each SB3 agent the grid trains, environment steps.
    """

    vehicles: tuple[str, ...] = tuple(VEHICLES)
    estimators: tuple[str, ...] = (ORACLE, RAW, "kf", "akf", "ekf")
    controllers: tuple[str, ...] = ("lqr",)
    seas: tuple[str, ...] = ("moderate",)
    sensors: tuple[str, ...] = ("default",)
    seeds: int = 5
    seconds: float | None = None
    timesteps: int = 100_000

    @classmethod
    def quick(cls) -> Grid:
        """All five vehicles, four estimators, LQR and PPO, the default sensors and 32 times
        their noise (where filtering matters), three 60-s episodes: minutes on 2 cores."""
        return cls(estimators=(ORACLE, RAW, "kf", "akf"), controllers=("lqr", "ppo"),
                   sensors=("default", "noise=32"), seeds=3, seconds=60.0, timesteps=20_000)

    def __post_init__(self) -> None:
        for name, values, known in (("vehicle", self.vehicles, VEHICLES),
                                    ("sea", self.seas, SEAS),
                                    ("estimator", self.estimators, (ORACLE, RAW, *ESTIMATORS))):
            unknown = [v for v in values if v not in known]
            if unknown:
                raise ValueError(f"unknown {name}(s) {unknown}: choose from {', '.join(known)}")
        if any(controller in ALIASES for controller in self.controllers):  # an old name
            object.__setattr__(self, "controllers", tuple(
                canonical(c) if c in ALIASES else c for c in self.controllers))
        for controller in self.controllers:
            if controller not in CONTROLLERS and not controller.startswith("sb3:"):
                raise ValueError(f"unknown controller {controller!r}: one of "
                                 f"{', '.join(CONTROLLERS)} or sb3:DIR (a 'marine train' output)")
        for sensor in self.sensors:
            parse_sensor(sensor)
        if not (isinstance(self.seeds, int) and self.seeds >= 1):
            raise ValueError(f"seeds={self.seeds!r} is invalid: an integer >= 1")
        if self.seconds is not None and not (math.isfinite(self.seconds) and self.seconds > 0):
            raise ValueError(f"seconds={self.seconds!r} is invalid: a positive duration in s")
        if not (isinstance(self.timesteps, int) and self.timesteps >= 1):
            raise ValueError(f"timesteps={self.timesteps!r} is invalid: an integer >= 1")

    def cells(self) -> list[dict[str, str]]:
        return [dict(zip(KEYS, values, strict=True))
                for values in itertools.product(self.vehicles, self.estimators, self.controllers,
                                                self.seas, self.sensors)]

    def settings(self) -> dict[str, Any]:
        """What makes rows comparable across runs (a resumed grid must match)."""
        return {"seeds": self.seeds, "seconds": self.seconds, "timesteps": self.timesteps}


def parse_sensor(spec: str) -> dict[str, float]:
    """``"noise=4+dropout=0.1"`` as ``{"noise": 4.0, "dropout": 0.1}``; ``"default"`` as {}.

    :raises ValueError: an unknown kind or a bad level, naming it.
    """
    if spec == "default":
        return {}
    out: dict[str, float] = {}
    for part in spec.split("+"):
        kind, _, level = part.partition("=")
        try:
            value = float(level)
        except ValueError:
            value = math.nan
        if kind not in DEGRADATIONS or not (math.isfinite(value) and value >= 0):
            raise ValueError(f"sensor degradation {part!r} is invalid: default, or kind=level "
                             f"joined by '+', kind one of {', '.join(DEGRADATIONS)} "
                             "(e.g. noise=4+dropout=0.1)")
        if kind == "dropout" and value >= 1:
            raise ValueError(f"sensor degradation {part!r} is invalid: dropout is a "
                             "probability < 1")
        out[kind] = value
    return out


def sensor_kwargs(spec: str, sensors: Any) -> dict[str, Any]:
    """The environment arguments of sensor degradation ``spec`` (see :data:`DEGRADATIONS`),
    relative to the default noise of ``sensors`` (the environment's ``SensorSuite``)."""
    from marine_envs.sensors import GaussianNoise

    levels = parse_sensor(spec)
    if not levels:
        return {}
    noise = [s.std for s in sensors.stages if isinstance(s, GaussianNoise)]
    std = noise[0] if noise else np.zeros(len(sensors.channels))
    per_channel = lambda k: {c: float(k * s) for c, s in zip(sensors.channels, std,  # noqa: E731
                                                              strict=True)}
    out: dict[str, Any] = {}
    if "noise" in levels:
        out["noise_std"] = per_channel(levels["noise"])
    if "quant" in levels:
        out["quantization"] = per_channel(levels["quant"])
    if "dropout" in levels:
        out["dropout"] = levels["dropout"]
    if "delay" in levels:
        out["delay"] = int(round(levels["delay"]))
    return out


def cell_key(cell: Mapping[str, Any]) -> tuple[str, ...]:
    return tuple(str(cell[k]) for k in KEYS)
