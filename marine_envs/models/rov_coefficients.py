"""The ROV's hydrodynamic coefficients as parameters of its compiled equations: what an
estimator that appends them to the state needs to run on the compiled equations
(:meth:`ROVModel.compiled_parameters <marine_envs.models.rov.ROVModel.compiled_parameters>`,
read by the estimators' compiled extended Kalman filter): how each filter's packed constants
follow its coefficients, and their exact Jacobian. What it needs of the ROV's module (its
compiled features, its morphing coefficients) is handed in: it imports none of it.
"""

from __future__ import annotations

import functools
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from ..compiled import jit, local_array
from .base import CompiledParameters, FloatArray, VehicleModel

#: Input step of the differences of a model's equations in its inputs (affine there: exact
#: for any step; a large one keeps the rounding of the equations' value out), input units.
INPUT_STEP = 1e3


def coefficient_parameters(model: VehicleModel, names: tuple[str, ...],
                           features: Callable[..., None], morphing: tuple[str, ...]
                           ) -> CompiledParameters | None:
    """The ROV's equations with hydrodynamic coefficients ``names`` estimated, as
    :meth:`ROVModel.rhs_with <marine_envs.models.rov.ROVModel.rhs_with>` defines them: a
    coefficient's value is its value at the current shape, i.e. the model in which it is the
    same in cruise and work shape.

    The packed constants of such a model are affine in the coefficients (the forces are linear
    in them, the mass matrix does not hold them), so each filter's are ``q_0 + D (theta -
    theta_0)``, with ``D`` sparse, from the model's own packing of a variant per coefficient.
    The parameter Jacobian is the exact ``[M(s)^-1 Phi; 0]``: ``Phi`` is one feature per
    coefficient in one force row, and the equations are affine in the forces, so one difference
    per force is ``M(s)^-1`` to rounding.

    :param model: an ROV model (:class:`~marine_envs.models.rov.ROVModel`).
    :param features: its compiled features ``features(x, u, d, F)`` (the regressors' rows).
    :param morphing: the coefficients that change with the shape (a ``work_`` value each).
    :return: None when a coefficient's regressor is not one feature, or a variant is refused.
    """
    made = _coefficient_tables(type(model), model.params, names, morphing)
    if made is None:
        return None
    constants, table = made
    n, n_u = len(model.state_names), len(model.input_names)
    n_features = model.features(model.x0).shape[-1]
    return CompiledParameters(_affine_constants,
                              _coefficient_jacobian(type(model).equations.core, features, n, n_u,
                                                    n_features), constants, table)


@functools.lru_cache(maxsize=16)
def _coefficient_tables(kind: type[VehicleModel], params: object, names: tuple[str, ...],
                        morphing: tuple[str, ...]
                        ) -> tuple[FloatArray, tuple[FloatArray, NDArray[np.int64]]] | None:
    """``(q_0, table)`` of :func:`coefficient_parameters` for the model ``kind(params)``.

    The table: floats ``[theta_0 (p) | q_0 of the changing constants (K) | D's entries]``,
    integers ``[K | feature (p) | force (p) | changing constants (K) | their first entry
    (K + 1) | each entry's coefficient]``."""
    model = kind(params)
    layout = _coefficient_layout(model, names)
    theta0 = np.array([getattr(model.params, k) for k in names], dtype=float)
    base = _shape_free(model, names, theta0, morphing)
    if layout is None or base is None:
        return None
    q0 = np.asarray(base.constants, dtype=float)
    columns = []
    for j in range(len(names)):
        step = -max(1.0, abs(theta0[j]))  # more dissipative: a variant the model accepts
        moved = _shape_free(model, names, theta0 + step * np.eye(len(names))[j], morphing)
        if moved is None:
            return None
        columns.append((np.asarray(moved.constants) - q0) / step)
    D = np.column_stack(columns)
    changing = np.flatnonzero((D != 0).any(axis=1))
    entries = [np.flatnonzero(D[i]) for i in changing]
    starts = np.cumsum([0] + [e.size for e in entries])
    coefficient = np.concatenate(entries)
    values = np.concatenate([D[i, e] for i, e in zip(changing, entries, strict=True)])
    floats = np.concatenate([theta0, q0[changing], values])
    ints = np.concatenate([[changing.size], *layout, changing, starts, coefficient])
    return q0, (floats, ints.astype(np.int64))


def _shape_free(model: VehicleModel, names: tuple[str, ...], values: FloatArray,
                morphing: tuple[str, ...]) -> VehicleModel | None:
    """``model`` with coefficients ``names`` at ``values`` in cruise and work shape; None when
    the model refuses them."""
    changes = {}
    for name, value in zip(names, values.tolist(), strict=True):
        changes[name] = value
        if name in morphing:  # the value at the current shape: the same in cruise and work
            changes[f"work_{name}"] = value
    try:
        return model.with_params(**changes)
    except ValueError:
        return None


def _coefficient_layout(model: VehicleModel, names: tuple[str, ...]
                        ) -> tuple[NDArray[np.int64], NDArray[np.int64]] | None:
    """The feature (row of :meth:`~marine_envs.models.rov.ROVModel.features`) and the force
    each coefficient's regressor is
    (:meth:`~marine_envs.models.rov.ROVModel.hydrodynamic_regressors`), found on random states
    with a current; None unless each is exactly one feature in one force."""
    rng = np.random.default_rng(0)
    x = rng.normal(0.0, 0.5, (4, len(model.state_names)))
    d = np.column_stack([rng.normal(0.0, 0.3, (4, 3)), rng.uniform(0.0, 1.0, 4)])
    features = model.features(x, d)  # (4, F)
    regressors = model.hydrodynamic_regressors(x, names, d)  # (4, n_u, p)
    rows, cols = [], []
    for j in range(len(names)):
        forces = np.flatnonzero(np.abs(regressors[:, :, j]).max(axis=0))
        if forces.size != 1:
            return None
        match = np.flatnonzero((features == regressors[:, forces[0], j, None]).all(axis=0))
        if match.size != 1:
            return None
        rows.append(match[0])
        cols.append(forces[0])
    return np.array(rows, dtype=np.int64), np.array(cols, dtype=np.int64)


@jit
def _affine_constants(theta, table, q):
    """``q = q_0 + D (theta - theta_0)`` on the constants that change (``table``: see
    ``_coefficient_tables``)."""
    floats, ints = table
    p, changing = theta.size, ints[0]
    index_at, start_at = 1 + 2 * p, 1 + 2 * p + changing
    coefficient_at, value_at = start_at + changing + 1, p + changing
    for e in range(changing):
        value = floats[p + e]
        for t in range(ints[start_at + e], ints[start_at + e + 1]):
            j = ints[coefficient_at + t]
            value += (theta[j] - floats[j]) * floats[value_at + t]
        q[ints[index_at + e]] = value


@functools.cache
def _coefficient_jacobian(core: Callable[..., None], features: Callable[..., None], n: int,
                          n_u: int, n_features: int
                          ) -> Callable[..., None]:
    """The parameter Jacobian of :func:`coefficient_parameters` for equations ``core`` of ``n``
    states, ``n_u`` inputs and ``n_features`` features."""
    n_values = n * (n_u + 1)  # f, then with each force moved

    @jit
    def jacobian(x, u, d, q, table, A):
        ints = table[1]
        p = A.shape[1] - n
        F, v, values = local_array(n_features), local_array(n_u), local_array(n_values)
        features(x, u, d, F)
        for k in range(n_u):
            v[k] = u[k]
        for k in range(n_u + 1):  # one call site: the equations are merged in once
            if k > 0:
                v[k - 1] = u[k - 1] + INPUT_STEP
            core(x, v, d, q, values[k * n:(k + 1) * n])
            if k > 0:
                v[k - 1] = u[k - 1]
        for j in range(p):  # d f / d u = [M(s)^-1; 0], exact: f is affine in u
            feature, force = F[ints[1 + j]], ints[1 + p + j] + 1
            for i in range(n):
                A[i, n + j] = (values[force * n + i] - values[i]) / INPUT_STEP * feature

    return jacobian
