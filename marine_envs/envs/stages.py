"""The step's stages, written once, on one boat's scalars: act (clip, scale, allocate), cost and
limits; integrate is the exact step of an affine model
(:func:`marine_envs.models.integrate.exact_step`) or RK4 of a model's equations
(:func:`marine_envs.compiled.rk4`).

The compiled step kernel (:mod:`marine_envs.envs.kernel`) calls them boat by boat, merged into
its loop; the functions ``*_rows`` apply them to every row of a batch, as
:func:`marine_envs.compiled.rows` applies a model's equations: they are the numpy path of
:class:`~marine_envs.envs.core.Simulator` (what the kernel does not run: a zig-zag rudder law,
sensor stages of the user's own) and the action map of
:class:`~marine_envs.envs.system.Actuation`. So both paths give the same numbers.
Arrays passed to the ``*_rows`` functions are C-contiguous float64 (the one layout compiled).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ..compiled import jit, step_rows
from ..models import VehicleModel
from ..models.effects import equations_of
from ..models.integrate import ExactStep, RK4Step, check_finite, exact_step


# -- one boat -------------------------------------------------------------------------------------
@jit
def clip(a, out):
    """``out`` = the actions ``a`` clipped to [-1, 1]; True when one was beyond."""
    clipped = False
    for j in range(a.size):
        value = a[j]
        if value > 1.0:
            value, clipped = 1.0, True
        elif value < -1.0:
            value, clipped = -1.0, True
        out[j] = value
    return clipped


@jit
def command(a, mid, scale, allocation, allocated, f, u):
    """The model inputs ``u`` of actions ``a``: each actuator's ``f = mid + scale * a``
    (actuator units; ``f`` may be ``a``), then, if ``allocated``, ``u = f @ allocation`` summed
    in the actuators' order, else ``u = f``."""
    for j in range(a.size):
        f[j] = mid[j] + scale[j] * a[j]
    if allocated:
        for i in range(u.size):
            total = 0.0
            for j in range(f.size):
                total += f[j] * allocation[j, i]
            u[i] = total
    else:
        for i in range(u.size):
            u[i] = f[i]


@jit
def act(a, mid, scale, allocation, allocated, f, u):
    """The commanded inputs ``u`` of actions ``a`` clipped to [-1, 1] (``f``: scratch of the
    actuators' size); True when an action was clipped."""
    clipped = clip(a, f)
    command(f, mid, scale, allocation, allocated, f, u)
    return clipped


@jit
def cost(w, ref, x, u, d):
    """Minus the weighted squares of ``[x u d]`` about the reference ``ref`` (the task's cost,
    weights ``w``), summed in the order of ``[x u d]``."""
    total = 0.0
    for k in range(x.size):
        total += (x[k] - ref[k]) * (x[k] - ref[k]) * w[k]
    n = x.size
    for k in range(u.size):
        total += (u[k] - ref[n + k]) * (u[k] - ref[n + k]) * w[n + k]
    n += u.size
    for k in range(d.size):
        total += (d[k] - ref[n + k]) * (d[k] - ref[n + k]) * w[n + k]
    return total


@jit
def exceeds(x, limited, low, high):
    """True when a watched state ``x[limited[k]]`` is outside ``[low[k], high[k]]``."""
    exceeded = False
    for k in range(limited.size):
        value = x[limited[k]]
        exceeded = exceeded or value < low[k] or value > high[k]
    return exceeded


# -- every row of a batch -------------------------------------------------------------------------
@jit(inline="never")  # called from Python: compiled once, not into every caller
def command_rows(A, mid, scale, allocation, allocated, U):
    """:func:`command` on every row of the actions ``A`` (not clipped)."""
    f = np.empty(A.shape[1])
    for b in range(A.shape[0]):
        command(A[b], mid, scale, allocation, allocated, f, U[b])


@jit(inline="never")
def act_rows(A, mid, scale, allocation, allocated, U, clipped):
    """:func:`act` on every row of the actions ``A``."""
    f = np.empty(A.shape[1])
    for b in range(A.shape[0]):
        clipped[b] = act(A[b], mid, scale, allocation, allocated, f, U[b])


@jit(inline="never")
def cost_rows(w, ref, X, U, D, reward):
    """:func:`cost` of every boat."""
    for b in range(X.shape[0]):
        reward[b] = cost(w, ref, X[b], U[b], D[b])


@jit(inline="never")
def limit_rows(X, limited, low, high, failed):
    """:func:`exceeds` of every boat."""
    for b in range(X.shape[0]):
        failed[b] = exceeds(X[b], limited, low, high)


class RowsStep:
    """A control period of every boat by a compiled one-boat step
    (:func:`~marine_envs.compiled.step_rows`): ``x_next = step(x, u, d)``.

    :raises FloatingPointError: a boat's state became NaN or inf (naming the boat).
    """

    def __init__(self, step: Callable[..., None], p: np.ndarray, h: float, substeps: int) -> None:
        self.rows, self.p, self.h, self.substeps = step_rows(step), np.atleast_2d(p), h, substeps

    @classmethod
    def of(cls, model: VehicleModel, integrate: ExactStep | RK4Step, dt: float
           ) -> RowsStep | None:
        """The compiled form of ``integrate``, or None for a model without compiled equations
        (its numpy ``rhs`` is integrated by :class:`~marine_envs.models.integrate.RK4Step`)."""
        if isinstance(integrate, ExactStep):
            return cls(exact_step, integrate.packed, dt, 1)
        if not equations_of(model):
            return None
        p = np.ascontiguousarray(model.constants, dtype=float)
        return cls(model.equations.rk4, p.reshape(-1, p.shape[-1]), integrate.h,
                   integrate.substeps)

    def __call__(self, x: np.ndarray, u: np.ndarray, d: np.ndarray) -> np.ndarray:
        out = np.empty(x.shape)
        self.rows(x, u, d, self.p, float(self.h), int(self.substeps), out)
        return check_finite(out)


__all__ = ["RowsStep", "act", "act_rows", "clip", "command", "command_rows", "cost",
           "cost_rows", "exceeds", "limit_rows"]
