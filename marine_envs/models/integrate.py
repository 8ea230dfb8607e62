"""Time integration of the models, written once: classical RK4 with sub-steps, and the exact
step of an affine model.

:func:`rk4` is the Runge-Kutta step of any numpy right-hand side: the manoeuvres, the
identification, the filters' predictions, the synthetic recordings, the diagnosis and the
environments' numpy path (:class:`RK4Step`) integrate with it. The environments' compiled step
kernel integrates a model's compiled equations with :func:`marine_envs.compiled.rk4`, the same
arithmetic in the same order (tested equal), so a model means the same trajectory everywhere.
:class:`ExactStep` is the zero-order-hold step of a linear (affine) model.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from .base import FloatArray, VehicleModel
from .linear import zoh

#: ``f(x, t) -> x_dot``: a right-hand side with everything but the state and time held.
RightHandSide = Callable[[FloatArray, float], FloatArray]


def rk4(f: RightHandSide, x: FloatArray, h: float, substeps: int = 1,
        t: float = 0.0) -> FloatArray:
    """``substeps`` classical Runge-Kutta steps of ``h`` seconds of ``x_dot = f(x, t)`` from
    time ``t`` (s); ``x`` may carry leading batch axes (one row per boat)."""
    for i in range(substeps):
        k = f(x, t)
        if i == 0 and k.flags.f_contiguous and not x.flags.f_contiguous:
            # a model working on state rows returns a transposed array: mixing memory
            # layouts would make every update below a slow strided loop
            x = np.asfortranarray(x)
        total = k.copy()
        k = f(x + 0.5 * h * k, t + 0.5 * h)
        total += 2 * k
        k = f(x + 0.5 * h * k, t + 0.5 * h)
        total += 2 * k
        k = f(x + h * k, t + h)
        total += k
        x = x + h / 6 * total
        t = t + h
    return x


class RK4Step:
    """One control period of a model by :func:`rk4`, inputs and disturbances held:
    ``x_next = step(xud)`` with ``xud = [x u d]`` stacked per boat (batch x (n_x + n_u + n_d)).

    :raises FloatingPointError: a boat's state became NaN or inf (naming the boat).
    """

    def __init__(self, model: VehicleModel, dt: float, substeps: int = 4) -> None:
        self.rhs, self.h, self.substeps = model.rhs, dt / substeps, substeps
        self.n_x, self.n_u = len(model.state_names), len(model.input_names)

    def __call__(self, xud: FloatArray) -> FloatArray:
        x, u, d = np.split(xud, [self.n_x, self.n_x + self.n_u], axis=1)
        rhs = self.rhs
        x = rk4(lambda z, _t: rhs(z, u, d), x, self.h, self.substeps)
        if not np.isfinite(x).all():
            bad = int(np.flatnonzero(~np.isfinite(x).all(axis=1))[0])
            raise FloatingPointError(f"simulation diverged: non-finite state {x[bad]} of boat "
                                     f"{bad} (a parameter or time step out of range?)")
        return x


class ExactStep:
    """Exact discretisation of an affine model with inputs and disturbances held over a step:
    ``x_next = [x u d] @ transition + offset``."""

    def __init__(self, model: VehicleModel, dt: float) -> None:
        A, B, E = model.linearize()
        nominal = np.concatenate([model.x0, model.u0, np.zeros(E.shape[1])])
        # the affine part: x_dot = A x + [B E] [u d] + c
        constant = model.rhs(model.x0, model.u0) - A @ model.x0 - B @ model.u0
        Phi, Gamma = zoh(A, np.column_stack([B, E, constant]), dt)
        self.transition = np.hstack([Phi, Gamma[:, :-1]]).T.copy()
        offset = Gamma[:, -1]
        self.offset = offset if np.abs(offset).max() > 1e-12 * (1 + np.abs(nominal).max()) \
            else None

    def __call__(self, xud: FloatArray) -> FloatArray:
        x_next = xud @ self.transition
        return x_next if self.offset is None else x_next + self.offset
