"""Time integration of the models, written once: classical RK4 with sub-steps, and the exact
step of an affine model.

:func:`rk4` is the Runge-Kutta step of any numpy right-hand side: the manoeuvres, the
identification, the filters' predictions, the synthetic recordings, the diagnosis and the
environments' numpy path (:class:`RK4Step`) integrate with it. The environments' compiled step
kernel integrates a model's compiled equations with :func:`marine_envs.compiled.rk4`, the same
arithmetic in the same order (tested equal), so a model means the same trajectory everywhere.
:class:`ExactStep` is the zero-order-hold step of a linear (affine) model, summed by
:func:`exact_step`, the compiled function the step kernel runs for every boat.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ..compiled import jit, step_rows
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
        return check_finite(rk4(lambda z, _t: rhs(z, u, d), x, self.h, self.substeps))


def check_finite(x: FloatArray) -> FloatArray:
    """``x`` (boats x states). :raises FloatingPointError: a boat's state is NaN or inf (naming
    the first such boat)."""
    finite = np.isfinite(x).all(axis=1)
    if not finite.all():
        bad = int(np.flatnonzero(~finite)[0])
        raise FloatingPointError(f"simulation diverged: non-finite state {x[bad]} of boat "
                                 f"{bad} (a parameter or time step out of range?)")
    return x


class ExactStep:
    """Exact discretisation of an affine model with inputs and disturbances held over a step:
    ``x_next = [x u d] @ transition + offset``, summed by :func:`exact_step` (the step kernel's
    arithmetic) on every row."""

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
        self.n_x, self.n_u = len(model.state_names), len(model.input_names)
        #: The ``p`` of :func:`exact_step`: the transition row by row, then the offset (zero
        #: when the model is linear).
        self.packed = np.concatenate([self.transition.ravel(),
                                      np.zeros(self.n_x) if self.offset is None else self.offset])

    def __call__(self, xud: FloatArray) -> FloatArray:
        """The next states of ``xud = [x u d]`` stacked, shape ``(..., n_x + n_u + n_d)``."""
        xud = np.asarray(xud, dtype=float)
        rows = np.array(xud.reshape(-1, xud.shape[-1]), order="C")  # (a fresh C array)
        x, u, d = np.split(rows, [self.n_x, self.n_x + self.n_u], axis=1)
        out = np.empty(x.shape)
        _exact_rows(np.ascontiguousarray(x), np.ascontiguousarray(u), np.ascontiguousarray(d),
                    self.packed[None, :], 0.0, 1, out)
        return out.reshape(*xud.shape[:-1], self.n_x)


@jit
def exact_step(x, u, d, p, h, substeps, out, work):
    """The exact (zero-order-hold) step of an affine model, ``out = [x u d] @ T + c``, with
    ``p`` = ``T`` row by row, then ``c`` (``ExactStep.packed``); ``work[0]`` holds
    ``[x u d]``. Each output is summed in the order of ``[x u d]``, then the offset; four
    outputs at a time in registers (sums kept in ``out`` would wait on memory at every term: it
    might alias ``p``). ``h`` and ``substeps`` are unused (the signature of
    :func:`marine_envs.compiled.rk4`'s steps)."""
    n_x, n_u, n_d = x.size, u.size, d.size
    n_in = n_x + n_u + n_d
    xud = work[0]
    for k in range(n_x):
        xud[k] = x[k]
    for k in range(n_u):
        xud[n_x + k] = u[k]
    for k in range(n_d):
        xud[n_x + n_u + k] = d[k]
    for i in range(0, n_x - 3, 4):
        t0 = t1 = t2 = t3 = 0.0
        for k in range(n_in):
            z, row = xud[k], k * n_x + i
            t0 += z * p[row]
            t1 += z * p[row + 1]
            t2 += z * p[row + 2]
            t3 += z * p[row + 3]
        c = n_in * n_x + i
        out[i], out[i + 1], out[i + 2], out[i + 3] = t0 + p[c], t1 + p[c + 1], t2 + p[c + 2], \
            t3 + p[c + 3]
    for i in range(n_x - n_x % 4, n_x):  # the rest, one at a time
        total = 0.0
        for k in range(n_in):
            total += xud[k] * p[k * n_x + i]
        out[i] = total + p[n_in * n_x + i]


def exact_constants(step: ExactStep, n_x: int) -> np.ndarray:
    """The ``p`` of :func:`exact_step`: the transition row by row, then the offset (zero when
    the model is linear)."""
    offset = np.zeros(n_x) if step.offset is None else step.offset
    return np.ascontiguousarray(np.concatenate([step.transition.ravel(), offset]), dtype=float)


#: :func:`exact_step` on every row (:func:`~marine_envs.compiled.step_rows`).
_exact_rows = step_rows(exact_step)
