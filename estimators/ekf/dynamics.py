"""The dynamics the compiled extended Kalman filter integrates and differences: a model's own
compiled equations ``core(x, u, d, q, out)`` (:mod:`marine_envs.compiled`), with estimated
parameters entering through the packed constants ``q``, set for each filter.

No vehicle is known here: a model with compiled equations runs compiled without parameters, and
with parameters where the model declares how they enter its constants
(:meth:`~marine_envs.models.base.VehicleModel.compiled_parameters`, e.g. the ROV's hydrodynamic
coefficients).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import NDArray

from marine_envs.compiled import jit
from marine_envs.models import VehicleModel

FloatArray = NDArray[np.float64]


@dataclasses.dataclass(frozen=True)
class CompiledDynamics:
    """What the kernels of a filter need to know about its dynamics (all functions compiled).

    :param f: ``f(x, u, d, q, out)``: the model states' derivative, a model's compiled
        equations with ``q`` its packed constants.
    :param integrate: :func:`marine_envs.compiled.rk4` of ``f``.
    :param prepare: ``prepare(theta, table, q)``: writes the constants of the parameter values
        ``theta`` into ``q`` (which holds those of the values the table was made at).
    :param parameter_jacobian: ``jac(x, u, d, q, table, A)``: writes ``d f / d theta`` into the
        last ``p`` columns of ``A`` ``(n, n + p)``.
    :param constants: ``q`` at the table's parameter values.
    :param table: what ``prepare`` and ``parameter_jacobian`` read: floats and integers.
    :param n, p: number of model states and of estimated parameters.
    """

    f: Callable[..., None]
    integrate: Callable[..., None]
    prepare: Callable[..., None]
    parameter_jacobian: Callable[..., None]
    constants: FloatArray
    table: tuple[FloatArray, NDArray[np.int64]]
    n: int
    p: int


def compiled_dynamics(model: VehicleModel, parameters: Sequence[str]) -> CompiledDynamics | None:
    """The compiled dynamics of ``model`` with ``parameters`` estimated, or None when there are
    none: the model has no compiled equations (or its ``rhs`` is not theirs, or its constants
    are per batch row), or it declares no compiled form of those parameters
    (:meth:`~marine_envs.models.base.VehicleModel.compiled_parameters`)."""
    equations = type(model).equations
    if equations is None or type(model).rhs is not VehicleModel.rhs:
        return None
    constants = np.asarray(model.constants, dtype=float)
    if constants.ndim != 1:  # parameters held per batch row
        return None
    n = len(model.state_names)
    if not parameters:
        return CompiledDynamics(equations.core, equations.rk4, same_constants,
                                no_parameters, constants.copy(),
                                (np.zeros(0), np.zeros(0, dtype=np.int64)), n, 0)
    declared = model.compiled_parameters(tuple(parameters))
    if declared is None:
        return None
    return CompiledDynamics(equations.core, equations.rk4, declared.prepare,
                            declared.jacobian, declared.constants, declared.table, n,
                            len(parameters))


@jit
def same_constants(theta, table, q):
    """Constants that do not depend on the parameters: left as they are."""


@jit
def no_parameters(x, u, d, q, table, A):
    """The parameter Jacobian of dynamics without parameters: nothing."""
