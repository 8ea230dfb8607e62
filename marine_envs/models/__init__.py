"""Vehicle models: pure physics, no Gymnasium (docs/architecture.md contract 1).

One module per vehicle holds its equations; the numerics every model and every layer shares are
written once beside them: :mod:`.integrate` (RK4, sub-steps, the exact step of a linear model),
:mod:`.linear` (ZOH discretisation, LQR / Riccati designs), :mod:`.kinematics` (rotations), and
:mod:`.effects`, the catalogue of physics a model may leave out.

>>> from marine_envs.models import get_model
>>> usv = get_model("usv", wn=0.7)      # parameter overrides by docs/models.md symbol
>>> A, B, E = usv.linearize()
"""

from __future__ import annotations

import importlib

from .base import MeasuredDisturbances, VehicleModel
from .linear import zoh
from .usv import USVModel, USVParams

#: Model name -> "module:class"; modules are imported on first use.
_MODELS: dict[str, str] = {
    "usv": "usv:USVModel",
    "hydrofoil": "hydrofoil:HydrofoilModel",
    "rov": "rov:ROVModel",
    "dp_vessel": "dp_vessel:DPVesselModel",
    "hovercraft": "hovercraft:HovercraftModel",
    "nomoto": "nomoto:NomotoModel",
    "mmg": "mmg:MMGModel",
}


def model_names() -> tuple[str, ...]:
    """Names accepted by :func:`get_model`."""
    return tuple(_MODELS)


def get_model(name: str, **params: float) -> VehicleModel:
    """The model called ``name`` with nominal parameters, optionally overridden by symbol.

    :raises ValueError: unknown model name or parameter, or a parameter out of range.
    """
    try:
        module, cls = _MODELS[name].split(":")
    except KeyError:
        raise ValueError(f"unknown model {name!r}; available: {', '.join(_MODELS)}") from None
    model = getattr(importlib.import_module(f".{module}", __name__), cls)()
    return model.with_params(**params) if params else model


__all__ = ["MeasuredDisturbances", "VehicleModel", "USVModel", "USVParams", "get_model",
           "model_names", "zoh"]
