"""Batched extended Kalman filter with optional parameters appended to the state.

Model (continuous dynamics, discrete measurements; filterpy's names)::

    x_dot   = f(x, u, theta) + w,      theta_dot = w_theta      (random walk, "artificial noise")
    y_k     = h(x_k) + v_k,            v_k ~ N(0, R)

The filter estimates the augmented state ``z = [x; theta]``. ``predict`` integrates the mean with
RK4 over the period (input held) and propagates the covariance with the transition matrix of the
Jacobian at the prior mean, ``Phi = exp(A dt)`` (Taylor series with scaling and squaring). The
update is in Joseph form and symmetrised. The morphing-robot patent, the DP wave-frequency patent
and the hovercraft EKF paper all identify parameters this way: hydrodynamic coefficients, wave
frequencies and manoeuvring derivatives.

A filter made by :meth:`~estimators.ekf.ExtendedKalmanFilter.from_model` of a model with
compiled equations runs predict and update compiled, filter by filter
(:mod:`estimators.ekf.kernels`: the same filter; on the joint ROV benchmark 12x faster for one
filter, 2.5x to 3x for batches of 64 to 1024); the numpy code here serves dynamics given as
Python callables and outputs that are not states.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from marine_envs.models import VehicleModel
from marine_envs.models.integrate import rk4
from marine_envs.sensors import Saturation

from ..base import Estimator, as_batch, check_covariance, check_measurement
from ..kalman import (
    _wrap,
    default_measurement_noise,
    default_process_noise,
    wrapped_channel_names,
)
from .dynamics import CompiledDynamics, compiled_dynamics
from .kernels import CompiledFilter
from .smoother import FilterResult, SmootherResult, rts_smooth

FloatArray = NDArray[np.float64]
#: ``f(x (R, n), u (R, n_u), theta (R, p)) -> x_dot (R, n)``. ``R`` is the batch size ``N`` or a
#: multiple ``N r`` of it, grouped by filter: row ``i r + j`` belongs to filter ``i``.
Dynamics = Callable[[FloatArray, FloatArray, FloatArray], FloatArray]
#: ``jacobian(x, u, theta) -> (df/dx (N, n, n), df/dtheta (N, n, p))``.
Jacobian = Callable[[FloatArray, FloatArray, FloatArray], tuple[FloatArray, FloatArray]]


class ExtendedKalmanFilter(Estimator):
    """A batch of ``N`` extended Kalman filters sharing one model; parameters may be appended to
    the state.

    :param f: continuous-time dynamics of the model states (see
        :data:`~estimators.ekf.filter.Dynamics`), vectorised.
    :param h: the measurement: a matrix ``H`` ``(m, n)`` (``y = H x``) or a vectorised callable
        ``h(x (N, n)) -> (N, m)`` (linearised by central differences at each update).
    :param dt: nominal period of :meth:`predict`, s.
    :param Q: process-noise covariance of the model states over one nominal period ``(n, n)``
        (a vector is a diagonal), in the states' units squared; scaled by ``dt / self.dt``.
    :param R: measurement-noise covariance ``(m, m)``, positive definite.
    :param n_inputs: number of inputs ``n_u``.
    :param state_names, measurement_names: names of the ``n`` model states and ``m`` channels.
    :param parameter_names: names of the ``p`` parameters appended to the state.
    :param parameter_noise: ``(p,)`` artificial random-walk intensity of each parameter, in its
        unit per sqrt(s): a prediction over ``dt`` adds ``parameter_noise**2 * dt`` to its
        variance. It lets the estimate follow a parameter that changes (and keeps the filter from
        "saturating" on old data); 0 (default) = constant parameters.
    :param jacobian: analytic Jacobians (see :data:`~estimators.ekf.filter.Jacobian`); default:
        central differences of ``f`` over ``[x; theta]`` in one batched call.
    :param parameter_jacobian: ``df/dtheta (N, n, p) = parameter_jacobian(x, u, theta)`` alone
        (e.g. exact regressors of parameters that enter linearly); the differences then cover
        ``x`` only.
    :param x0, P0: default initial augmented estimate ``(n + p,)`` and covariance.
    :param angular: measured channels (names or indices) that are wrapped angles: their
        innovation is wrapped to (-pi, pi].
    :param substeps: RK4 steps per prediction.
    :param batch_size: number of filters ``N``.
    :param divergence_ratio, reinitialise_diverged: as :class:`~estimators.kalman.KalmanFilter`.
    :param compiled: ``f`` as compiled dynamics without parameters (its ``f(z, u, d, q, out)``
        reading no disturbance ``d``): predict and update then run compiled
        (:mod:`estimators.ekf.kernels`) when ``h`` is a matrix selecting states.
    :param sensor_range: ``(low, high)`` ``(m,)`` each: the channels' full-scale range, in their
        units. A reading at or beyond it is a saturated sensor's, which says only that the value
        is beyond the range: it is taken as missing, not as a measurement (the filter would
        otherwise pull its estimate, and states it cannot see, towards the clipped value).
    """

    def __init__(self, f: Dynamics, h: ArrayLike | Callable[[FloatArray], FloatArray], *,
                 dt: float, Q: ArrayLike, R: ArrayLike, n_inputs: int,
                 state_names: Sequence[str], measurement_names: Sequence[str],
                 parameter_names: Sequence[str] = (), parameter_noise: ArrayLike | None = None,
                 jacobian: Jacobian | None = None,
                 parameter_jacobian: Dynamics | None = None, x0: ArrayLike | None = None,
                 P0: ArrayLike | None = None, angular: Sequence[str | int] = (),
                 substeps: int = 1, batch_size: int = 1, divergence_ratio: float = 10.0,
                 reinitialise_diverged: bool = False,
                 compiled: CompiledDynamics | None = None,
                 sensor_range: tuple[ArrayLike, ArrayLike] | None = None) -> None:
        n, p, m = len(state_names), len(parameter_names), len(measurement_names)
        if not (math.isfinite(dt) and dt > 0):
            raise ValueError(f"dt={dt!r} is invalid: must be > 0 s")
        if not (isinstance(substeps, int) and substeps >= 1):
            raise ValueError(f"substeps={substeps!r} is invalid: an integer >= 1")
        if not divergence_ratio > 1:
            raise ValueError(f"divergence_ratio={divergence_ratio!r} is invalid: must be > 1")
        self.f, self.jacobian, self.parameter_jacobian = f, jacobian, parameter_jacobian
        self.dt, self.substeps = float(dt), substeps
        self.n_inputs, self._n, self._p = int(n_inputs), n, p
        self.model_state_names = tuple(state_names)
        self.parameter_names = tuple(parameter_names)
        self.state_names = self.model_state_names + self.parameter_names
        self.measurement_names = tuple(measurement_names)
        if callable(h):
            self.h, self._H = h, None
        else:
            H = np.atleast_2d(np.asarray(h, dtype=float))
            if H.shape != (m, n):
                raise ValueError(f"H has shape {H.shape}; expected ({m}, {n}): "
                                 f"{m} measurement names, {n} state names")
            self.h, self._H = None, np.hstack([H, np.zeros((m, p))])
        self.Q = check_covariance("Q", Q, n)
        self.R = check_covariance("R", R, m)
        if np.linalg.eigvalsh(self.R).min() <= 0:
            raise ValueError("R must be positive definite: every measurement has some noise")
        q = np.zeros(p) if parameter_noise is None else np.asarray(parameter_noise, dtype=float)
        if q.shape != (p,) or not (np.isfinite(q).all() and (q >= 0).all()):
            raise ValueError(f"parameter_noise must be {p} finite values >= 0 "
                             f"({', '.join(self.parameter_names)}); got {parameter_noise!r}")
        self.parameter_noise = q
        self.x0 = np.zeros(n + p) if x0 is None else as_batch("x0", x0, 1, n + p)[0].copy()
        if not np.isfinite(self.x0).all():
            raise ValueError("x0 has non-finite entries")
        self.P0 = np.eye(n + p) if P0 is None else check_covariance("P0", P0, n + p)
        self.angular = np.array([self.measurement_names.index(a) if isinstance(a, str) else a
                                 for a in angular], dtype=np.intp)
        self.divergence_ratio = float(divergence_ratio)
        self.reinitialise_diverged = reinitialise_diverged
        self.sensor_range = _sensor_range(sensor_range, m)
        self._compiled: CompiledFilter | None = None  # set by from_model where it can
        selection = self._H is not None and p == 0 and bool(np.all(
            (self._H == 0) | (self._H == 1)) and np.all(self._H.sum(axis=1) == 1))
        if compiled is not None and compiled.p == 0 and compiled.n == n and selection:
            self._disturbance_row = np.zeros(0)
            self._compiled = CompiledFilter(compiled, np.argmax(self._H, axis=1), 0)
            self._compiled.compile(m, self.n_inputs)  # now: a caller may say it compiles
        self.bind(batch_size)

    # -- construction from the project's models and environments --------------------------
    @classmethod
    def from_model(cls, model: VehicleModel, dt: float, *, measured: Sequence[str],
                   Q: ArrayLike, R: ArrayLike, parameters: Sequence[str] = (),
                   parameter_noise: ArrayLike | None = None,
                   disturbance: ArrayLike | None = None, compiled: bool = True,
                   **kwargs: Any) -> ExtendedKalmanFilter:
        """The filter of a vehicle model (:mod:`marine_envs.models`), optionally with some of its
        parameters (names as in ``model.params``) appended to the state.

        The dynamics are ``model.rhs_with(x, u, d, {name: theta})``, their parameter Jacobian
        ``model.parameter_jacobian`` where the model has an exact one; ``d`` is the filter's
        attribute ``disturbance`` ``(N, n_d)`` (zeros unless given; assign to it between
        predictions, e.g. the ROV's morph command). ``x0`` defaults to the model's nominal state
        and its parameters' values. Other arguments as the constructor.

        :param measured: the measured outputs, by name (``model.output_names``).
        :param compiled: predict and update in compiled code (:mod:`estimators.ekf.kernels`)
            where the model's equations are compiled, the parameters are none or the ROV's
            hydrodynamic coefficients, the measured outputs are states and no Jacobian is given
            (else, or False: the numpy path, the reference; :attr:`compiled` says which runs).
            The compiled path gives the numpy path's estimates to rounding (amplified by the
            differences), leaves a filter whose innovation covariance is not positive definite
            as it was, and flags it, and a covariance with a diagonal entry <= 0, as diverged.
        """
        compiled = compiled and not {"jacobian", "parameter_jacobian"} & kwargs.keys()
        unknown = sorted(set(measured) - set(model.output_names))
        if unknown:
            raise ValueError(f"measured channel(s) {unknown} are not outputs of model "
                             f"{model.name!r}: {', '.join(model.output_names)}")
        parameters = tuple(parameters)
        nominal = [getattr(model.params, name, None) for name in parameters]
        bad = [n for n, v in zip(parameters, nominal, strict=True)
               if not isinstance(v, int | float) or isinstance(v, bool)]
        if bad:
            scalars = [f.name for f in dataclasses.fields(model.params)
                       if isinstance(getattr(model.params, f.name), int | float)]
            raise ValueError(f"parameter(s) {bad} are unknown or not scalar in model "
                             f"{model.name!r}; its scalar parameters: {', '.join(scalars)}")
        ekf: ExtendedKalmanFilter

        def f(x: FloatArray, u: FloatArray, theta: FloatArray) -> FloatArray:
            d = np.repeat(ekf.disturbance, x.shape[0] // ekf.batch_size, axis=0)
            if not parameters:
                return model.rhs(x, u, d)
            return model.rhs_with(x, u, d, dict(zip(parameters, theta.T, strict=True)))

        def parameter_jacobian(x: FloatArray, u: FloatArray, theta: FloatArray) -> FloatArray:
            d = np.repeat(ekf.disturbance, x.shape[0] // ekf.batch_size, axis=0)
            return model.parameter_jacobian(x, u, d, dict(zip(parameters, theta.T, strict=True)))

        exact = parameters and model.parameter_jacobian(
            model.x0, model.u0, None, dict(zip(parameters, nominal, strict=True))) is not None
        if exact:
            kwargs.setdefault("parameter_jacobian", parameter_jacobian)
        rows = [model.output_names.index(c) for c in measured]
        if model.output_names == model.state_names:
            h: Any = np.eye(len(model.state_names))[rows]
        else:
            def h(x: FloatArray) -> FloatArray:
                return model.output(x)[:, rows]
        kwargs.setdefault("x0", np.concatenate([model.x0, np.asarray(nominal, dtype=float)]))
        ekf = cls(f, h, dt=dt, Q=Q, R=R, n_inputs=len(model.input_names),
                  state_names=model.state_names, measurement_names=measured,
                  parameter_names=parameters, parameter_noise=parameter_noise, **kwargs)
        n_d = len(model.disturbance_names)
        ekf._disturbance_row = np.zeros(n_d) if disturbance is None else \
            as_batch("disturbance", disturbance, 1, n_d)[0].copy()
        ekf.disturbance = np.tile(ekf._disturbance_row, (ekf.batch_size, 1))
        own = cls.predict is ExtendedKalmanFilter.predict and \
            cls.update is ExtendedKalmanFilter.update
        if compiled and own and ekf._H is not None:
            dynamics = compiled_dynamics(model, parameters)
            if dynamics is not None:
                ekf._compiled = CompiledFilter(dynamics, rows, n_d)
        return ekf

    @classmethod
    def for_env(cls, env: Any, Q: ArrayLike | None = None, R: ArrayLike | None = None,
                **kwargs: Any) -> ExtendedKalmanFilter:
        """A filter for a marine environment: its model, control period and sensor channels.

        :param Q: process noise per control period; default: the env's own disturbances held
            over a period, through the model linearised at the task's reference.
        :param R: measurement noise; default: each sensor's noise variance plus its quantization
            step squared over 12.
        :param kwargs: as :meth:`from_model` (``parameters``, ``parameter_noise``, ``P0``, ...).
        """
        system = env.unwrapped.system
        Q = default_process_noise(system) if Q is None else Q
        R = default_measurement_noise(system) if R is None else R
        kwargs.setdefault("angular", wrapped_channel_names(system))
        kwargs.setdefault("sensor_range", sensor_range(system))
        kwargs.setdefault("substeps", system.substeps)
        params = tuple(kwargs.get("parameters", ()))
        model = system.model
        x_ref = np.concatenate([system.task.x_ref, [getattr(model.params, p) for p in params]])
        kwargs.setdefault("x0", x_ref)
        return cls.from_model(model, system.dt, measured=system.channels, Q=Q, R=R, **kwargs)

    # -- views ------------------------------------------------------------------------------
    @property
    def compiled(self) -> bool:
        """Whether predict and update run compiled (:meth:`from_model`)."""
        return self._compiled is not None

    @property
    def parameters(self) -> FloatArray:
        """Estimated parameters ``(N, p)``."""
        return self.x[:, self._n:]

    @property
    def transition(self) -> FloatArray:
        """``Phi`` ``(N, n + p, n + p)`` of the last prediction (identity before the first); the
        smoother needs it, the filter itself only its model rows."""
        if self._transition is None:
            n, size = self._n, self._n + self._p
            self._transition = np.tile(np.eye(size), (self.batch_size, 1, 1))
            self._transition[:, :n] = self._transition_model_rows
        return self._transition

    @property
    def std(self) -> FloatArray:
        """Standard deviation of every estimated state and parameter, ``(N, n + p)``."""
        return np.sqrt(np.maximum(np.diagonal(self.P, axis1=1, axis2=2), 0.0))

    @property
    def parameter_std(self) -> FloatArray:
        """Standard deviation of the estimated parameters, ``(N, p)``."""
        return self.std[:, self._n:]

    # -- the estimator contract ------------------------------------------------------------
    def bind(self, batch_size: int) -> None:
        if not (isinstance(batch_size, int | np.integer) and batch_size >= 1):
            raise ValueError(f"batch_size={batch_size!r} is invalid: an integer >= 1")
        m, size = len(self.measurement_names), self._n + self._p
        self.x = np.tile(self.x0, (batch_size, 1))
        self.P = np.tile(self.P0, (batch_size, 1, 1))
        self.innovation = np.zeros((batch_size, m))
        self.nis = np.zeros(batch_size)
        self.dof = np.zeros(batch_size, dtype=np.intp)
        self._nis_mean = np.full(batch_size, float(m))
        self.diverged = np.zeros(batch_size, dtype=bool)
        self._transition: FloatArray | None = np.tile(np.eye(size), (batch_size, 1, 1))
        if hasattr(self, "_disturbance_row"):
            self.disturbance = np.tile(self._disturbance_row, (batch_size, 1))

    def reset(self, x0: ArrayLike | None = None, P0: ArrayLike | None = None,
              idx: ArrayLike | None = None) -> None:
        rows = np.arange(self.batch_size) if idx is None else np.atleast_1d(np.asarray(idx))
        if rows.dtype == bool:
            rows = np.flatnonzero(rows)
        size = self._n + self._p
        x = self.x0 if x0 is None else np.asarray(x0, dtype=float)
        if x.shape not in ((size,), (rows.size, size)) or not np.isfinite(x).all():
            raise ValueError(f"x0 must be {size} finite values ({', '.join(self.state_names)}) "
                             f"or ({rows.size}, {size}); got shape {x.shape}")
        self.x[rows] = x
        self.P[rows] = self.P0 if P0 is None else check_covariance("P0", P0, size)
        self.innovation[rows] = 0
        self._nis_mean[rows] = len(self.measurement_names)
        self.diverged[rows] = False

    def predict(self, u: ArrayLike, dt: float | None = None) -> FloatArray:
        u, dt = self._input(u, dt)
        if self._compiled is not None:
            Q = (self.Q + self.Q.T) * (0.5 * dt / self.dt)  # symmetric, as P's halves are
            self.x, self.P, T = self._compiled.predict(self.x, self.P, u, self.disturbance, dt,
                                                       self.substeps, Q,
                                                       self.parameter_noise**2 * dt)
            self._transition_model_rows, self._transition = T, None
            return self.x
        n = self._n
        T = _transition_rows(self._state_jacobian(self.x, u) * dt)  # Phi = [[T], [0, I]]
        self.x = self._propagate(self.x, u, dt)
        # Phi P Phi' with the parameters' identity rows exploited (5x cheaper for 13 + 18)
        TP = T @ self.P
        P = self.P.copy()
        P[:, :n, :n] = TP @ T.transpose(0, 2, 1)
        P[:, :n, n:] = TP[:, :, n:]
        P[:, n:, :n] = TP[:, :, n:].transpose(0, 2, 1)
        self.P = self._add_process_noise(P, dt)
        self._transition_model_rows, self._transition = T, None  # assembled when asked for
        return self.x

    def update(self, y: ArrayLike, mask: ArrayLike | None = None) -> tuple[FloatArray, FloatArray]:
        y, valid = check_measurement(y, mask, self.measurement_names, self.batch_size)
        if self.sensor_range is not None:  # a saturated reading bounds the value, no more
            low, high = self.sensor_range
            valid = valid & (y > low) & (y < high)
        if self._compiled is not None:  # H selects states: y_hat = x[measured]
            e = self._innovation(y, self.x[:, self._compiled.measured], valid)
            self.x, self.P, S, nis, healthy = self._compiled.update(self.x, self.P, e, valid,
                                                                    self.R)
            self.innovation, self.innovation_cov, self.nis = e, S, nis
            self.dof = valid.sum(axis=1)
            self._check_health(healthy)
            return self.x, self.P
        H, y_hat = self._measurement_jacobian(self.x)
        e = self._innovation(y, y_hat, valid)
        H = H * valid[:, :, None]  # missing channels: zero rows of H and unit noise: zero gain
        R = self._masked_noise(valid)
        PHt = self.P @ H.transpose(0, 2, 1)
        S = H @ PHt + R
        K, S_inv_e = self._gain(PHt, S, e)
        self.x = self.x + (K @ e[:, :, None])[:, :, 0]
        IKH = np.eye(self._n + self._p) - K @ H
        P = IKH @ self.P @ IKH.transpose(0, 2, 1) + K @ R @ K.transpose(0, 2, 1)
        self.P = (P + P.transpose(0, 2, 1)) * 0.5
        self._record_update(e, S, S_inv_e, valid)
        return self.x, self.P

    # -- offline use -------------------------------------------------------------------------
    def filter(self, u: ArrayLike, y: ArrayLike, mask: ArrayLike | None = None,
               x0: ArrayLike | None = None, P0: ArrayLike | None = None,
               progress: Callable[[int], None] | None = None) -> FilterResult:
        """Run the filter over a record from a :meth:`reset`: at step ``k`` update with ``y[k]``,
        then predict over :attr:`dt` with ``u[k]`` (``u[T-1]`` is not used).

        :param u: inputs ``(T, N, n_u)`` or ``(T, n_u)`` (the same for every filter).
        :param y: measurements ``(T, N, m)`` or ``(T, m)``; NaN marks a missing sample.
        :param mask: ``(T, N, m)`` or ``(T, m)`` valid channels, or None.
        :param progress: called with the number of steps done after each step (e.g. a bar).
        """
        u = self._record("u", u, self.n_inputs)
        y = self._record("y", y, len(self.measurement_names))
        if u.shape[0] != y.shape[0]:
            raise ValueError(f"u has {u.shape[0]} steps but y has {y.shape[0]}")
        mask = None if mask is None else self._record("mask", mask, y.shape[2])
        T, N, size = y.shape[0], self.batch_size, self._n + self._p
        out = {k: np.empty((T, N, size)) for k in ("x", "x_pred")}
        out.update({k: np.empty((T, N, size, size)) for k in ("P", "P_pred")})
        out["transition"] = np.empty((max(T - 1, 0), N, size, size))
        out["innovation"] = np.empty(y.shape)
        out["nis"], out["dof"] = np.empty((T, N)), np.empty((T, N), dtype=np.intp)
        self.reset(x0, P0)
        for k in range(T):
            out["x_pred"][k], out["P_pred"][k] = self.x, self.P
            self.update(y[k], None if mask is None else mask[k])
            out["x"][k], out["P"][k] = self.x, self.P
            out["innovation"][k], out["nis"][k], out["dof"][k] = \
                self.innovation, self.nis, self.dof
            if k < T - 1:
                self.predict(u[k])
                out["transition"][k] = self.transition
            if progress is not None:
                progress(k + 1)
        return FilterResult(**out, state_names=self.state_names)

    def smooth(self, u: ArrayLike, y: ArrayLike, mask: ArrayLike | None = None,
               x0: ArrayLike | None = None, P0: ArrayLike | None = None) -> SmootherResult:
        """:meth:`filter`, then the Rauch-Tung-Striebel smoother (:func:`rts_smooth`)."""
        return rts_smooth(self.filter(u, y, mask, x0, P0))

    # -- internals ---------------------------------------------------------------------------
    def _record(self, name: str, value: ArrayLike, width: int) -> FloatArray:
        a = np.asarray(value, dtype=float)
        if a.ndim == 2:
            a = np.broadcast_to(a[:, None, :], (a.shape[0], self.batch_size, a.shape[1]))
        if a.ndim != 3 or a.shape[1:] != (self.batch_size, width):
            raise ValueError(f"{name} has shape {np.shape(value)}; expected (T, {width}) or "
                             f"(T, {self.batch_size}, {width})")
        return a

    def held_input_response(self, z: ArrayLike, u: ArrayLike) -> FloatArray:
        """``Gamma = int_0^dt exp(A s) ds`` ``(N, n, n)``, s: how much one period moves the
        model states per unit state derivative held over it, linearised about each row of the
        states ``z`` ``(N, n + p)`` with inputs ``u`` ``(N, n_u)`` (the augmented exponential
        the transition ``Phi = exp(A dt)`` comes from; exact for a stiff mode, where the
        trapezoid ``dt (Phi + I) / 2`` is not)."""
        z, u = np.atleast_2d(np.asarray(z, dtype=float)), np.atleast_2d(np.asarray(u, dtype=float))
        A = self._state_jacobian(z, u)[:, :, :self._n]
        unit = np.broadcast_to(np.eye(self._n), A.shape)
        return _transition_rows(np.concatenate([A, unit], axis=2) * self.dt)[:, :, self._n:]

    def _input(self, u: ArrayLike, dt: float | None) -> tuple[FloatArray, float]:
        dt = self.dt if dt is None else float(dt)
        if not (math.isfinite(dt) and dt > 0):
            raise ValueError(f"dt={dt!r} is invalid: must be > 0 s")
        u = as_batch("u", u, self.batch_size, self.n_inputs)
        if not np.isfinite(u).all():
            raise ValueError("u has non-finite entries")
        return u, dt

    def _propagate(self, z: FloatArray, u: FloatArray, dt: float) -> FloatArray:
        """Augmented states ``z`` ``(R, n + p)`` after ``dt`` s of RK4 with inputs ``u`` held."""
        return rk4(lambda z, _t: self._z_dot(z, u), z, dt / self.substeps, self.substeps)

    def _add_process_noise(self, P: FloatArray, dt: float) -> FloatArray:
        """``P`` plus the model states' and the parameters' process noise over ``dt``,
        symmetrised."""
        n, size = self._n, self._n + self._p
        P[:, :n, :n] += self.Q * (dt / self.dt)
        P[:, range(n, size), range(n, size)] += self.parameter_noise**2 * dt
        return (P + P.transpose(0, 2, 1)) * 0.5

    def _z_dot(self, z: FloatArray, u: FloatArray) -> FloatArray:
        out = np.zeros_like(z)
        out[:, :self._n] = self.f(z[:, :self._n], u, z[:, self._n:])
        return out

    def _state_jacobian(self, z: FloatArray, u: FloatArray) -> FloatArray:
        """``d f / d [x; theta]`` ``(N, n, n + p)`` (the parameters' own rows are zero)."""
        n = self._n
        x, theta = z[:, :n], z[:, n:]
        if self.jacobian is not None:
            return np.concatenate(self.jacobian(x, u, theta), axis=2)
        if self.parameter_jacobian is None:
            return self._differences(z, u, n)
        return np.concatenate([self._differences(z, u, n, columns=n),
                               self.parameter_jacobian(x, u, theta)], axis=2)

    def _differences(self, z: FloatArray, u: FloatArray, n: int,
                     columns: int | None = None) -> FloatArray:
        """Central differences of ``f`` over the first ``columns`` entries of ``z`` (all by
        default), evaluated in one batched call: ``(N, n, columns)``."""
        N, size = z.shape[0], columns or z.shape[1]
        step = 1e-6 * np.maximum(1.0, np.abs(z[:, :size]))  # (N, size)
        offsets = np.zeros((N, size, z.shape[1]))
        offsets[:, range(size), range(size)] = step
        points = np.concatenate([z[:, None] + offsets, z[:, None] - offsets], axis=1)
        points = points.reshape(N * 2 * size, z.shape[1])
        values = self.f(points[:, :n], np.repeat(u, 2 * size, axis=0), points[:, n:])
        values = values.reshape(N, 2, size, n)
        return ((values[:, 0] - values[:, 1]) / (2 * step[:, :, None])).transpose(0, 2, 1)

    def _measurement_jacobian(self, z: FloatArray) -> tuple[FloatArray, FloatArray]:
        """``(H (N, m, n + p), h(z) (N, m))`` at the estimates."""
        if self._H is not None:
            return np.broadcast_to(self._H, (z.shape[0], *self._H.shape)), z @ self._H.T
        N, n = z.shape[0], self._n
        x = z[:, :n]
        step = 1e-6 * np.maximum(1.0, np.abs(x))
        offsets = np.einsum("ni,ij->nij", step, np.eye(n))
        points = np.concatenate([x[:, None] + offsets, x[:, None] - offsets], axis=1)
        values = self.h(points.reshape(N * 2 * n, n)).reshape(N, 2, n, -1)
        H = np.zeros((N, values.shape[-1], n + self._p))
        H[:, :, :n] = ((values[:, 0] - values[:, 1]) / (2 * step[:, :, None])).transpose(0, 2, 1)
        return H, self.h(x)

    def _innovation(self, y: FloatArray, y_hat: FloatArray,
                    valid: NDArray[np.bool_]) -> FloatArray:
        e = np.where(valid, y - y_hat, 0.0)
        if self.angular.size:
            e[:, self.angular] = _wrap(e[:, self.angular])
        return e

    def _masked_noise(self, valid: NDArray[np.bool_]) -> FloatArray:
        """``R`` per filter with missing channels' rows and columns replaced by the identity."""
        m = valid.shape[1]
        both = valid[:, :, None] & valid[:, None, :]
        return np.where(both, self.R, 0.0) + np.where(valid, 0.0, 1.0)[:, :, None] * np.eye(m)

    @staticmethod
    def _gain(cross: FloatArray, S: FloatArray, e: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Kalman gain ``K = C S^-1`` ``(N, n, m)`` from the state-measurement cross covariance
        ``C`` and ``S^-1 e``, in one batched solve."""
        sol = np.linalg.solve(S, np.concatenate([cross.transpose(0, 2, 1), e[:, :, None]],
                                                axis=2))
        return sol[:, :, :-1].transpose(0, 2, 1), sol[:, :, -1]

    def _record_update(self, e: FloatArray, S: FloatArray, S_inv_e: FloatArray,
                       valid: NDArray[np.bool_]) -> None:
        self.innovation, self.innovation_cov = e, S
        self.nis = np.einsum("ij,ij->i", e, S_inv_e)
        self.dof = valid.sum(axis=1)
        self._check_health()

    def _check_health(self, finite: NDArray[np.bool_] | None = None) -> None:
        """Flag filters whose estimate is not finite (or, given ``finite``, not that) or whose
        running NIS mean (over ~20 updates) exceeds ``divergence_ratio`` times its expected
        value."""
        w = 0.05
        seen = self.dof > 0
        self._nis_mean = np.where(seen, (1 - w) * self._nis_mean + w * self.nis, self._nis_mean)
        if finite is None:
            finite = np.isfinite(self.x).all(axis=1) & np.isfinite(self.P).all(axis=(1, 2))
        bad = ~finite | (self._nis_mean > self.divergence_ratio * len(self.measurement_names))
        if bad.any():
            self.diverged = self.diverged | bad
            if self.reinitialise_diverged:
                self.reset(idx=np.flatnonzero(bad))
                self.diverged = self.diverged | bad


def _transition_rows(A: FloatArray) -> FloatArray:
    """The model rows ``[Phi_x, Gamma]`` ``(N, n, n + p)`` of ``exp([[A_x, A_theta], [0, 0]])``
    for ``A = [A_x, A_theta]`` ``(N, n, n + p)`` (one step's ``df/dz dt``).

    An 8th-order Taylor series with scaling and squaring: truncation below 1e-11 relative, and
    much cheaper than scipy's batched Pade for a filter's small steps. Powers of the augmented
    matrix keep zero parameter rows, ``[[X, Y], [0, 0]]^k = [[X^k, X^(k-1) Y], [0, 0]]``, so only
    the model rows are computed; a squaring is ``[X, Y] -> [X X, X Y + Y]``.
    """
    n = A.shape[1]
    norm = float(np.abs(A[:, :, :n]).sum(axis=2).max()) if A.size else 0.0
    squarings = max(0, math.ceil(math.log2(norm / 0.25))) if norm > 0.25 else 0
    A = A / 2**squarings
    X = A[:, :, :n]
    term, out = A, A.copy()
    out[:, :, :n] += np.eye(n)
    for k in range(2, 9):
        term = X @ term / k
        out += term
    for _ in range(squarings):
        squared = out[:, :, :n] @ out
        squared[:, :, n:] += out[:, :, n:]
        out = squared
    return out


def _sensor_range(sensor_range: tuple[ArrayLike, ArrayLike] | None, m: int
                  ) -> tuple[FloatArray, FloatArray] | None:
    """``(low, high)`` as two ``(m,)`` arrays with ``low < high`` (None: no range)."""
    if sensor_range is None:
        return None
    low, high = (np.broadcast_to(np.asarray(a, dtype=float), (m,)).copy() for a in sensor_range)
    if np.isnan(low).any() or np.isnan(high).any() or not (low < high).all():
        raise ValueError(f"sensor_range=({low.tolist()}, {high.tolist()}) is invalid: "
                         f"{m} lows below {m} highs")
    return low, high


def sensor_range(system: Any) -> tuple[FloatArray, FloatArray] | None:
    """The full-scale range ``(low, high)`` of the environment's sensor channels (their
    :class:`~marine_envs.sensors.Saturation` stages; None without one)."""
    m = len(system.sensors.channels)
    low, high = np.full(m, -np.inf), np.full(m, np.inf)
    for stage in system.sensors.stages:
        if isinstance(stage, Saturation):
            low = np.maximum(low, np.ravel(stage.low))
            high = np.minimum(high, np.ravel(stage.high))
    return (low, high) if np.isfinite(low).any() or np.isfinite(high).any() else None
