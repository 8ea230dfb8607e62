"""Vehicle models: pure physics, no Gymnasium (ARCHITECTURE.md contract 1).

>>> from marine_envs.models import get_model
>>> usv = get_model("usv", wn=0.7)      # parameter overrides by MODELS.md symbol
>>> A, B, E = usv.linearize()
"""

from __future__ import annotations

from .base import VehicleModel
from .usv import USVModel, USVParams

_MODELS: dict[str, type[VehicleModel]] = {"usv": USVModel}
#: Models specified in MODELS.md that later issues add.
PLANNED = ("hydrofoil", "rov", "dp_vessel", "hovercraft")


def model_names() -> tuple[str, ...]:
    """Names accepted by :func:`get_model`."""
    return tuple(_MODELS)


def get_model(name: str, **params: float) -> VehicleModel:
    """The model called ``name`` with nominal parameters, optionally overridden by symbol.

    :raises ValueError: unknown model name or parameter, or a parameter out of range.
    """
    try:
        cls = _MODELS[name]
    except KeyError:
        hint = f" ({name!r} is planned but not implemented yet)" if name in PLANNED else ""
        raise ValueError(f"unknown model {name!r}{hint}; available: {', '.join(_MODELS)}") from None
    model = cls()
    return model.with_params(**params) if params else model


__all__ = ["VehicleModel", "USVModel", "USVParams", "get_model", "model_names"]
