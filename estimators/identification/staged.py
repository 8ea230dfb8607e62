"""Staged identification: :func:`identify_staged` chains :func:`~.joint_ekf.identify_ekf` runs
(e.g. the linear coefficients from a mild manoeuvre, then the nonlinear ones from harder ones),
each stage (:class:`Stage`) starting from the previous stages' estimates.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from marine_envs.models import VehicleModel

from .data import Segment, _scales, _values, as_segments, check_parameters
from .joint_ekf import identify_ekf
from .result import Identification


@dataclasses.dataclass(frozen=True)
class Stage:
    """One stage of a staged identification.

    :param name: label.
    :param segments: the data of this stage.
    :param parameters: the parameters identified in this stage.
    :param prior: for parameters estimated in an earlier stage: ``"posterior"`` starts from that
        stage's estimate and std (Bayesian chaining; correlations are dropped), ``"initial"``
        from its estimate with the initial prior std (a re-estimation that does not trust the
        earlier std, e.g. when that stage held other parameters at wrong values).
    :param description: why this stage, for reports.
    """

    name: str
    segments: tuple[Segment, ...]
    parameters: tuple[str, ...]
    prior: str = "initial"
    description: str = ""

    def __post_init__(self) -> None:
        if self.prior not in ("posterior", "initial"):
            raise ValueError(f"prior={self.prior!r} is invalid: 'posterior' or 'initial'")
        object.__setattr__(self, "segments", tuple(as_segments(self.segments)))
        object.__setattr__(self, "parameters", tuple(self.parameters))


def identify_staged(model: VehicleModel, stages: Sequence[Stage], *,
                    initial: Mapping[str, float] | None = None,
                    prior_std: Mapping[str, float] | None = None,
                    **kwargs: Any) -> list[Identification]:
    """Stages of :func:`identify_ekf`, each using the previous stages' estimates.

    In stage ``j`` the parameters of earlier stages that are not identified again are held at
    their latest estimates, those not yet identified at ``initial``; parameters identified again
    start from their latest estimate (see :attr:`Stage.prior`).

    :param initial: initial guesses of every staged parameter (default the model's values).
    :param prior_std: initial prior std by name (default ``|initial|``).
    :param kwargs: passed to :func:`identify_ekf` (``reference``, ``measurement_std``, ...).
    """
    stages = list(stages)
    if not stages:
        raise ValueError("no stages given")
    every = tuple(dict.fromkeys(n for s in stages for n in s.parameters))
    check_parameters(model, every)
    current = dict(zip(every, _values(model, every, initial, "initial"), strict=True))
    std0 = dict(zip(every, _scales(every, np.array(list(current.values())), prior_std),
                    strict=True))
    posterior: dict[str, tuple[float, float]] = {}
    results = []
    for stage in stages:
        held = {k: v for k, v in current.items() if k not in stage.parameters}
        staged_model = model.with_params(**held) if held else model
        start = {k: current[k] for k in stage.parameters}
        std = {k: (posterior[k][1] if stage.prior == "posterior" and k in posterior
                   else std0[k]) for k in stage.parameters}
        result = identify_ekf(staged_model, list(stage.segments), stage.parameters,
                              initial=start, prior_std=std, **kwargs)
        result.info.update(stage=stage.name, held={k: float(v) for k, v in held.items()},
                           description=stage.description)
        results.append(result)
        for k, v, s in zip(result.names, result.estimate, result.std, strict=True):
            current[k] = float(v)
            posterior[k] = (float(v), float(s))
    return results
