"""Linear observers on quantized network data: the shared held-input machinery and the classical
Luenberger observer used as the baseline of the USV observer patent (docs/models.md 1.4-1.6).

Both observers of this package's quantized-signal study are linear ODEs driven by data that stay
constant between two samples: the input ``u`` (held by the actuator) and what last arrived over
the network. Between samples the ODE is therefore integrated *exactly* (zero-order hold, one
matrix exponential per step size, cached): the result does not depend on the step size, which
explicit Euler would only approximate, and costs the same two matrix products per step.

The classical network sends every measured channel through the static uniform quantizer
``q(y) = mu2 * round(y / mu2)`` (one step ``mu2`` for all channels, as the USV observer patent's
quantizer 2), and the Luenberger observer ``x_hat' = A x_hat + B u + L (q(y) - C x_hat)`` uses
that. Its gain comes from pole placement (:func:`observer_gain`); any other gain (a steady-state
Kalman gain, say) can be passed directly.
"""

from __future__ import annotations

import math
from abc import abstractmethod
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from marine_envs.models import zoh
from marine_envs.models.usv import USVModel
from marine_envs.sensors import quantize

from .base import Estimator, FloatArray, as_batch

#: Default observer poles of the USV Luenberger baseline, 1/s. [PROPOSED] Real, distinct and as
#: slow as the PD observer's slow modes (|Re| 0.1-0.15), so both settle alike: faster poles
#: amplify the unknown wave disturbance in the sway estimate (poles -0.3..-0.7 gave a 3.6 times
#: larger wave-induced floor in the corrected setting of the USV observer patent's example).
USV_OBSERVER_POLES: tuple[float, ...] = (-0.15, -0.2, -0.25, -0.3, -0.35)

#: An estimate larger than this (in any state's SI unit) counts as diverged.
DIVERGENCE_LIMIT = 1e6


def check_positive(name: str, value: float) -> float:
    """``value`` as a float if it is finite and > 0, else a ValueError naming it."""
    if not (isinstance(value, int | float | np.integer | np.floating) and math.isfinite(value)
            and value > 0):
        raise ValueError(f"{name}={value!r} is invalid: must be finite and > 0")
    return float(value)


def check_steps(name: str, value: float | ArrayLike) -> float | FloatArray:
    """A quantization step: a positive scalar, or one positive step per observer ``(N,)``."""
    if np.ndim(value) == 0:
        return check_positive(name, value)  # type: ignore[arg-type]
    steps = np.asarray(value, dtype=float)
    if steps.ndim != 1 or steps.size == 0 or not np.all(np.isfinite(steps) & (steps > 0)):
        raise ValueError(f"{name}={value!r} is invalid: a step > 0, or one per observer (N,)")
    return steps


def steps_per_row(name: str, steps: float | FloatArray, batch_size: int) -> float | FloatArray:
    """``steps`` ready to broadcast over ``(N, channels)``: a scalar or an ``(N, 1)`` column."""
    if np.ndim(steps) == 0:
        return steps
    if np.size(steps) != batch_size:
        raise ValueError(f"{name} has {np.size(steps)} steps but the batch has {batch_size} "
                         "observers")
    return np.asarray(steps)[:, None]


class HeldInputObserver(Estimator):
    """A batch of linear observers ``z' = F z + G_u u + G_h h``, integrated exactly.

    ``h`` (``held``, ``(N, n_h)``) is the data received at the last :meth:`update`; ``u`` is the
    input passed to :meth:`predict`. Subclasses define :meth:`_receive` (measurement -> ``held``),
    :meth:`_estimate` (``z`` -> ``x``) and :meth:`_restart` (``x0`` -> ``z``, ``held``).

    A masked or non-finite measurement channel holds its last valid value (sample-and-hold at
    the sensor), so a missing sample never injects NaN; before the first valid sample the held
    value is the one predicted from the initial estimate.

    :param F: ``(n_z, n_z)`` state matrix of the observer, 1/s.
    :param G_u: ``(n_z, n_u)`` input matrix.
    :param G_h: ``(n_z, n_h)`` matrix of the held data.
    :param C: ``(m, n)`` output matrix in the estimator's state and measurement order.
    :param dt: nominal step of :meth:`predict`, s.
    :param batch_size: number of observers allocated at construction (see :meth:`bind`).
    """

    def __init__(self, F: ArrayLike, G_u: ArrayLike, G_h: ArrayLike, C: ArrayLike, dt: float,
                 state_names: Sequence[str], measurement_names: Sequence[str],
                 batch_size: int = 1) -> None:
        self.F, self.G_u, self.G_h = (np.asarray(a, dtype=float) for a in (F, G_u, G_h))
        self.C = np.asarray(C, dtype=float)
        self.dt = check_positive("dt", dt)
        self.state_names, self.measurement_names = tuple(state_names), tuple(measurement_names)
        if self.C.shape != (len(self.measurement_names), len(self.state_names)):
            raise ValueError(f"C has shape {self.C.shape}; expected "
                             f"({len(self.measurement_names)}, {len(self.state_names)})")
        self._steps: dict[float, tuple[FloatArray, FloatArray, FloatArray]] = {}
        self.bind(batch_size)

    # -- the Estimator contract -----------------------------------------------------------------
    def bind(self, batch_size: int) -> None:
        if int(batch_size) < 1:
            raise ValueError(f"batch_size={batch_size!r} is invalid: must be >= 1")
        n, m = len(self.state_names), len(self.measurement_names)
        self.x = np.zeros((batch_size, n))
        self.P = np.full((batch_size, n, n), np.nan)
        self.innovation = np.zeros((batch_size, m))
        self.diverged = np.zeros(batch_size, dtype=bool)
        self.z = np.zeros((batch_size, self.F.shape[0]))
        self.held = np.zeros((batch_size, self.G_h.shape[1]))
        self.y_held = np.zeros((batch_size, m))
        self.reset()

    def reset(self, x0: ArrayLike | None = None, P0: ArrayLike | None = None,
              idx: ArrayLike | None = None) -> None:
        """Restart observers ``idx`` (all if None) from ``x0`` (zeros if None), in the model's
        state order and units. Observers have no covariance: ``P0`` is accepted and ignored."""
        rows = np.arange(self.batch_size) if idx is None else np.asarray(idx, dtype=np.intp)
        x0 = np.zeros(len(self.state_names)) if x0 is None else x0
        x0 = np.array(as_batch("x0", x0, rows.size, len(self.state_names)))
        if not np.isfinite(x0).all():
            raise ValueError("x0 has non-finite entries")
        self.y_held[rows] = x0 @ self.C.T
        self.innovation[rows] = 0.0
        self._restart(rows, x0)
        self._refresh()

    def predict(self, u: ArrayLike, dt: float | None = None) -> FloatArray:
        """Integrate exactly over ``dt`` s (default :attr:`dt`) with ``u`` ``(N, n_u)`` and the last
        received data held; returns ``x``."""
        u = as_batch("u", u, self.batch_size, self.G_u.shape[1])
        Phi, Gam_u, Gam_h = self._step_matrices(self.dt if dt is None else check_positive("dt", dt))
        self.z = self.z @ Phi.T + u @ Gam_u.T + self.held @ Gam_h.T
        self._refresh()
        return self.x

    def update(self, y: ArrayLike, mask: ArrayLike | None = None) -> tuple[FloatArray, FloatArray]:
        """Receive measurement ``y`` ``(N, m)`` (model units, order :attr:`measurement_names`);
        channels where ``mask`` is False or ``y`` is not finite hold their last value. The
        estimate itself moves only in :meth:`predict` (the data enter as held forcing)."""
        y = self._valid(y, mask)
        self.innovation = np.where(self._fresh, y - self.x @ self.C.T, 0.0)
        self.held = self._receive(y)
        return self.x, self.P

    # -- for subclasses -------------------------------------------------------------------------
    @abstractmethod
    def _restart(self, rows: NDArray[np.intp], x0: FloatArray) -> None:
        """Set ``z[rows]`` and ``held[rows]`` for a restart from ``x0`` ``(len(rows), n)``."""

    @abstractmethod
    def _receive(self, y: FloatArray) -> FloatArray:
        """The data held until the next sample, from the valid measurement ``y``."""

    @abstractmethod
    def _estimate(self, z: FloatArray) -> FloatArray:
        """The estimate ``x`` (model order and units) of the observer state ``z``."""

    # -- helpers --------------------------------------------------------------------------------
    def _valid(self, y: ArrayLike, mask: ArrayLike | None) -> FloatArray:
        """``y`` with missing channels replaced by their held values (and the hold refreshed)."""
        y = as_batch("y", y, self.batch_size, len(self.measurement_names))
        fresh = np.isfinite(y)
        if mask is not None:
            fresh &= as_batch("mask", np.asarray(mask, dtype=bool), *y.shape) > 0
        self._fresh = fresh
        self.y_held = np.where(fresh, y, self.y_held)
        return self.y_held

    def _step_matrices(self, dt: float) -> tuple[FloatArray, FloatArray, FloatArray]:
        if dt not in self._steps:
            Phi, Gam = zoh(self.F, np.hstack([self.G_u, self.G_h]), dt)
            n_u = self.G_u.shape[1]
            self._steps[dt] = (Phi, Gam[:, :n_u], Gam[:, n_u:])
        return self._steps[dt]

    def _refresh(self) -> None:
        self.x = self._estimate(self.z)
        self.diverged = ~(np.abs(self.x).max(axis=1) <= DIVERGENCE_LIMIT)  # NaN counts too


def observer_gain(A: ArrayLike, C: ArrayLike, poles: Sequence[float]) -> FloatArray:
    """Luenberger gain ``L`` placing the eigenvalues of ``A - L C`` at ``poles`` (1/s).

    :raises ValueError: ``(A, C)`` cannot be given those poles (unobservable mode, or a pole
        repeated more often than the number of outputs).
    """
    import scipy.signal  # (here: `import estimators` need not load it)

    A, C = np.asarray(A, dtype=float), np.asarray(C, dtype=float)
    if len(poles) != A.shape[0]:
        raise ValueError(f"poles has {len(poles)} entries; expected {A.shape[0]}")
    return scipy.signal.place_poles(A.T, C.T, np.asarray(poles, dtype=float)).gain_matrix.T


class LuenbergerObserver(HeldInputObserver):
    """Classical Luenberger observer fed the classical network's data: every output quantized.

    ``x_hat' = A x_hat + B u + L (q(y) - C x_hat)`` with ``q(y) = mu2 * round(y / mu2)`` on every
    channel (the USV observer patent's static quantizer 2 applied to the whole output, as a network
    without the patent's error-transmission scheme would do). ``q(y)`` is held between samples.

    :param A: ``(n, n)`` state matrix, 1/s.
    :param B: ``(n, n_u)`` input matrix.
    :param C: ``(m, n)`` output matrix.
    :param L: ``(n, m)`` observer gain (see :func:`observer_gain`).
    :param mu2: quantization step of every channel, in the channel's unit (rad, rad/s); a scalar,
        or one step per observer ``(N,)`` (then the batch size is ``N``).
    :param dt: nominal step of :meth:`predict`, s.
    :param state_names: names of the states (default ``x0, x1, ...``).
    :param measurement_names: names of the measured channels (default ``y0, y1, ...``).
    """

    def __init__(self, A: ArrayLike, B: ArrayLike, C: ArrayLike, L: ArrayLike, *,
                 mu2: float | ArrayLike = 0.5, dt: float = 1e-3,
                 state_names: Sequence[str] | None = None,
                 measurement_names: Sequence[str] | None = None) -> None:
        A, B, C, L = (np.atleast_2d(np.asarray(a, dtype=float)) for a in (A, B, C, L))
        n, m = A.shape[0], C.shape[0]
        for name, a, shape in (("A", A, (n, n)), ("B", B, (n, B.shape[1])), ("C", C, (m, n)),
                               ("L", L, (n, m))):
            if a.shape != shape:
                raise ValueError(f"{name} has shape {a.shape}; expected {shape}")
        self.mu2 = check_steps("mu2", mu2)
        self.A, self.B, self.L = A, B, L
        super().__init__(A - L @ C, B, L, C, dt,
                         state_names or [f"x{i}" for i in range(n)],
                         measurement_names or [f"y{i}" for i in range(m)], np.size(mu2))

    @classmethod
    def for_usv(cls, model: USVModel | None = None, *,
                poles: Sequence[float] = USV_OBSERVER_POLES, mu2: float | ArrayLike = 0.5,
                dt: float = 1e-3) -> LuenbergerObserver:
        """The USV baseline: model matrices of ``model`` (default: the USV observer patent's), the
        patent's measured channels ``[r, psi, p, phi]``, gain placed at ``poles`` (1/s).

        :param mu2: quantization step, rad and rad/s.
        :param dt: nominal step, s.
        """
        model = USVModel() if model is None else model
        A, B, _ = model.linearize()
        C = model.C
        return cls(A, B, C, observer_gain(A, C, poles), mu2=mu2, dt=dt,
                   state_names=model.state_names, measurement_names=model.measured_names)

    def bind(self, batch_size: int) -> None:
        self._mu2 = steps_per_row("mu2", self.mu2, batch_size)
        super().bind(batch_size)

    @property
    def q_y(self) -> NDArray[np.float64]:
        """The quantized outputs last received ``(N, m)``."""
        return self.held

    def _restart(self, rows: NDArray[np.intp], x0: FloatArray) -> None:
        self.z[rows], self.held[rows] = x0, x0 @ self.C.T  # no innovation before the first sample

    def _receive(self, y: FloatArray) -> FloatArray:
        return quantize(y, self._mu2)

    def _estimate(self, z: FloatArray) -> FloatArray:
        return z
