"""Gymnasium environments: a batched simulation core with single and native vector front ends,
one module per vehicle."""

from __future__ import annotations

from collections.abc import Mapping

from . import dp_vessel, hovercraft, hydrofoil, rov, usv
from .base import MarineEnv, MarineVectorEnv, vector_env
from .core import Simulator
from .dp_vessel import DPVesselEnv, DPVesselVectorEnv
from .hovercraft import HovercraftEnv, HovercraftVectorEnv
from .hydrofoil import HydrofoilEnv, HydrofoilVectorEnv
from .rov import ROVEnv, ROVVectorEnv
from .system import Actuation, System, Task
from .usv import USVEnv, USVVectorEnv

#: Model name (``marine_envs.models.get_model``) -> the module of its environment.
_VEHICLES = {"usv": usv, "hydrofoil": hydrofoil, "rov": rov, "dp_vessel": dp_vessel,
             "hovercraft": hovercraft}


def task_weights(model: str) -> tuple[Mapping[str, float], Mapping[str, float]]:
    """The default task cost of the environment of model ``model``: ``(state weights, input
    weights)`` by name (1/unit^2; the Bryson weights each environment documents).

    :raises ValueError: a model without an environment.
    """
    if model not in _VEHICLES:
        raise ValueError(f"model {model!r} has no environment; with one: {', '.join(_VEHICLES)}")
    module = _VEHICLES[model]
    return module.DEFAULT_STATE_WEIGHTS, module.DEFAULT_INPUT_WEIGHTS


__all__ = ["Actuation", "DPVesselEnv", "DPVesselVectorEnv", "HovercraftEnv",
           "HovercraftVectorEnv", "HydrofoilEnv", "HydrofoilVectorEnv", "MarineEnv",
           "MarineVectorEnv", "ROVEnv", "ROVVectorEnv", "Simulator", "System", "Task", "USVEnv",
           "USVVectorEnv", "task_weights", "vector_env"]
