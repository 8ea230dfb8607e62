"""The DP observer whose WF model is retuned: a batch of Kalman filters on the DP vessel model that
separate the low-frequency motion from the WF motion, with per-row peak frequencies."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from marine_envs.models.dp_vessel import DPVesselModel, DPVesselParams

from ..base import Estimator, as_batch, check_covariance
from ..kalman import KalmanFilter, _wrap, held_noise_covariance
from .config import CHANNELS, DEG, SEED_OMEGA_INITIAL, FloatArray, _require_positive, _rows, _vector


class WaveFilter(Estimator):
    """The DP vessel's wave filter: a batch of Kalman filters on
    :class:`~marine_envs.models.dp_vessel.DPVesselModel` (15 states: LF position and heading,
    velocities, bias, WF states) measuring ``north, east, psi`` = LF + WF motion + noise. Each
    row has its own WF peak frequencies ``w0``; :meth:`set_wave_frequencies` changes them without
    touching the estimate or its covariance (the LF state is kept).

    The matrices for a ``w0`` are :meth:`KalmanFilter.from_model
    <estimators.kalman.KalmanFilter.from_model>`'s (the model linearised about ``x_ref, u_ref``,
    zero-order hold); the process noise is the model's own: unit-intensity white noise on its six
    disturbances, held over each period.

    :param dt: period of :meth:`predict`, s.
    :param w0: initial WF peak frequencies (north, east, psi), rad/s (default: the DP
        wave-frequency patent's initial guess 0.4, 0.4, 0.55).
    :param params: the vessel's parameters (default :class:`DPVesselParams`); its ``w0`` is
        replaced per row.
    :param R: measurement-noise covariance ``(3, 3)`` or its diagonal (m^2, m^2, rad^2); default
        the DP environment's sensors (0.032 m, 0.032 m, 0.1 deg).
    :param x_ref, u_ref: linearisation point (default: the model's nominal point).
    :param x0, P0: default initial estimate ``(15,)`` and covariance of :meth:`reset`.
    :param batch_size: number of filters ``N``.
    :param divergence_ratio: as :class:`~estimators.kalman.KalmanFilter`.
    """

    measurement_names = CHANNELS

    def __init__(self, dt: float = 0.5, w0: ArrayLike = SEED_OMEGA_INITIAL, *,
                 params: DPVesselParams | None = None, R: ArrayLike | None = None,
                 x_ref: ArrayLike | None = None, u_ref: ArrayLike | None = None,
                 x0: ArrayLike | None = None, P0: ArrayLike | None = None,
                 batch_size: int = 1, divergence_ratio: float = 10.0) -> None:
        _require_positive("dt", dt)
        self.dt = float(dt)
        self.model = DPVesselModel(params)
        self.state_names = self.model.state_names
        n = len(self.state_names)
        self.R = check_covariance("R", np.array([1e-3, 1e-3, (0.1 * DEG) ** 2])
                                  if R is None else R, 3)
        if np.linalg.eigvalsh(self.R).min() <= 0:
            raise ValueError("R must be positive definite: every measurement has some noise")
        self.x_ref = self.model.x0 if x_ref is None else _vector("x_ref", x_ref, n)
        self.u_ref = self.model.u0 if u_ref is None else _vector("u_ref", u_ref, 3)
        self.x0 = self.x_ref.copy() if x0 is None else _vector("x0", x0, n)
        self.P0 = _default_P0(self.model) if P0 is None else check_covariance("P0", P0, n)
        if not divergence_ratio > 1:
            raise ValueError(f"divergence_ratio={divergence_ratio!r} is invalid: must be > 1")
        self.divergence_ratio = float(divergence_ratio)
        self.w0_initial = _frequencies("w0", w0)
        self._cache: dict[tuple[float, float, float], tuple[FloatArray, ...]] = {}
        self.H, self.d = self._matrices(self.w0_initial)[3:5]
        self.bind(batch_size)

    @classmethod
    def for_env(cls, env: Any, w0: ArrayLike = SEED_OMEGA_INITIAL, **kwargs: Any) -> WaveFilter:
        """:meth:`for_system` of a ``DPVessel-v0`` environment (possibly wrapped)."""
        return cls.for_system(env.unwrapped.system, w0, **kwargs)

    @classmethod
    def for_system(cls, system: Any, w0: ArrayLike = SEED_OMEGA_INITIAL,
                   **kwargs: Any) -> WaveFilter:
        """A wave filter for the DP vessel's system (``env.unwrapped.system``): its vessel
        parameters (except ``w0``), control period, linearisation point and sensor noise."""
        from ..kalman import default_measurement_noise

        if not isinstance(system.model, DPVesselModel):
            raise ValueError(f"a wave filter needs the DP vessel; the env's model is "
                             f"{system.model.name!r}")
        if tuple(system.sensors.channels) != CHANNELS:
            raise ValueError(f"the env's sensors give {tuple(system.sensors.channels)}; the "
                             f"wave filter needs {CHANNELS}")
        kwargs.setdefault("R", default_measurement_noise(system))
        kwargs.setdefault("x_ref", system.task.x_ref)
        kwargs.setdefault("u_ref", system.task.u_ref)
        return cls(system.dt, w0, params=system.model.params, **kwargs)

    # -- per-w0 matrices ---------------------------------------------------------------------
    def _matrices(self, w0: FloatArray) -> tuple[FloatArray, ...]:
        """``(F, G, c, H, d, Q)`` for peak frequencies ``w0`` (cached)."""
        key = tuple(float(v) for v in w0)
        if key not in self._cache:
            model = self.model.with_params(w0=key)
            A, _, E = model.linearize(self.x_ref, self.u_ref)
            Q = held_noise_covariance(A, E, self.dt, np.eye(E.shape[1]) / self.dt)
            # a floor per state in its own unit (a floor from the trace would be ~1 m^2 per
            # step here: the bias's N^2 dwarf the positions' m^2)
            Q = Q + np.diag(1e-9 * np.diag(Q) + 1e-14)
            kf = KalmanFilter.from_model(model, self.dt, measured=CHANNELS, Q=Q, R=self.R,
                                         x_ref=self.x_ref, u_ref=self.u_ref)
            if len(self._cache) > 64:
                self._cache.clear()
            self._cache[key] = (kf.F, kf.G, kf.c, kf.H, kf.d, kf.Q)
        return self._cache[key]

    @property
    def wave_frequencies(self) -> FloatArray:
        """Each filter's WF peak frequencies ``(N, 3)``, rad/s."""
        return self._w0

    def set_wave_frequencies(self, w0: ArrayLike, idx: ArrayLike | None = None) -> None:
        """Use peak frequencies ``w0`` ``(3,)`` or ``(len(idx), 3)`` (rad/s) in filters ``idx``
        (all if None) from the next prediction on; estimates and covariances are kept."""
        rows = _rows(idx, self.batch_size)
        values = np.asarray(w0, dtype=float)
        values = np.broadcast_to(values, (rows.size, 3)) if values.shape == (3,) else values
        if values.shape != (rows.size, 3):
            raise ValueError(f"w0 has shape {np.shape(w0)}; expected (3,) or ({rows.size}, 3)")
        for r, w in zip(rows, values, strict=True):
            F, G, c, _, _, Q = self._matrices(_frequencies("w0", w))
            self._w0[r], self._F[r], self._G[r], self._c[r], self._Q[r] = w, F, G, c, Q

    # -- the estimator contract ----------------------------------------------------------
    def bind(self, batch_size: int) -> None:
        if not (isinstance(batch_size, int | np.integer) and batch_size >= 1):
            raise ValueError(f"batch_size={batch_size!r} is invalid: an integer >= 1")
        F, G, c, _, _, Q = self._matrices(self.w0_initial)
        self._w0 = np.tile(self.w0_initial, (batch_size, 1))
        self._F, self._G = np.tile(F, (batch_size, 1, 1)), np.tile(G, (batch_size, 1, 1))
        self._c, self._Q = np.tile(c, (batch_size, 1)), np.tile(Q, (batch_size, 1, 1))
        self.x = np.tile(self.x0, (batch_size, 1))
        self.P = np.tile(self.P0, (batch_size, 1, 1))
        self.innovation = np.zeros((batch_size, 3))
        self.nis = np.zeros(batch_size)
        self._nis_mean = np.full(batch_size, 3.0)
        self.diverged = np.zeros(batch_size, dtype=bool)

    def reset(self, x0: ArrayLike | None = None, P0: ArrayLike | None = None,
              idx: ArrayLike | None = None) -> None:
        """Restart filters ``idx`` from ``x0, P0`` with the initial ``w0``."""
        rows = _rows(idx, self.batch_size)
        n = self.x.shape[1]
        x = self.x0 if x0 is None else np.asarray(x0, dtype=float)
        if x.shape not in ((n,), (rows.size, n)) or not np.isfinite(x).all():
            raise ValueError(f"x0 must be {n} finite values or ({rows.size}, {n}); got shape "
                             f"{x.shape}")
        self.x[rows] = x
        self.P[rows] = self.P0 if P0 is None else check_covariance("P0", P0, n)
        self.set_wave_frequencies(self.w0_initial, rows)
        self.innovation[rows], self._nis_mean[rows], self.diverged[rows] = 0.0, 3.0, False

    def predict(self, u: ArrayLike, dt: float | None = None) -> FloatArray:
        if dt is not None and not math.isclose(dt, self.dt):
            raise ValueError(f"dt={dt} differs from the filter's period {self.dt} s")
        u = as_batch("u", u, self.batch_size, 3)
        self.x = np.einsum("nij,nj->ni", self._F, self.x) + \
            np.einsum("nij,nj->ni", self._G, u) + self._c
        P = self._F @ self.P @ self._F.transpose(0, 2, 1) + self._Q
        self.P = (P + P.transpose(0, 2, 1)) * 0.5
        return self.x

    def update(self, y: ArrayLike, mask: ArrayLike | None = None) -> tuple[FloatArray, FloatArray]:
        N = self.batch_size
        y = np.asarray(y, dtype=float)
        if y.shape != (N, 3):
            raise ValueError(f"y has shape {y.shape}; expected ({N}, 3): {', '.join(CHANNELS)}")
        valid = np.isfinite(y)
        if mask is not None:
            valid &= as_batch("mask", mask, N, 3).astype(bool)
        e = np.where(valid, y - (self.x @ self.H.T + self.d), 0.0)
        e[:, 2] = np.where(valid[:, 2], _wrap(e[:, 2]), 0.0)  # the compass wraps at +-pi
        # missing channels: zero rows of H and unit noise give them exactly zero gain
        H = self.H[None] * valid[:, :, None]
        both = valid[:, :, None] & valid[:, None, :]
        R = np.where(both, self.R, 0.0) + np.where(valid, 0.0, 1.0)[:, :, None] * np.eye(3)
        PHt = self.P @ H.transpose(0, 2, 1)
        S = H @ PHt + R
        sol = np.linalg.solve(S, np.concatenate([PHt.transpose(0, 2, 1), e[:, :, None]], axis=2))
        K, S_inv_e = sol[:, :, :-1].transpose(0, 2, 1), sol[:, :, -1]
        self.x = self.x + (K @ e[:, :, None])[:, :, 0]
        IKH = np.eye(self.x.shape[1]) - K @ H
        P = IKH @ self.P @ IKH.transpose(0, 2, 1) + K @ R @ K.transpose(0, 2, 1)
        self.P = (P + P.transpose(0, 2, 1)) * 0.5
        self.innovation, self.nis = e, np.einsum("ij,ij->i", e, S_inv_e)
        self._nis_mean = np.where(valid.any(axis=1), 0.95 * self._nis_mean + 0.05 * self.nis,
                                  self._nis_mean)
        finite = np.isfinite(self.x).all(axis=1) & np.isfinite(self.P).all(axis=(1, 2))
        self.diverged |= ~finite | (self._nis_mean > self.divergence_ratio * 3)
        return self.x, self.P

    @property
    def low_frequency(self) -> FloatArray:
        """The LF position and heading estimate ``(N, 3)`` (m, m, rad)."""
        return self.x[:, 0:3]

    @property
    def wave_motion(self) -> FloatArray:
        """The WF motion estimate ``(N, 3)`` (m, m, rad)."""
        return self.x[:, 12:15]


def _frequencies(name: str, value: ArrayLike) -> FloatArray:
    w = _vector(name, value, 3)
    if not (w > 0).all():
        raise ValueError(f"{name}={np.asarray(value).tolist()} is invalid: peak frequencies "
                         "must be > 0 rad/s")
    return w


def _default_P0(model: DPVesselModel) -> FloatArray:
    """Initial covariance: 5 m, 5 m, 5 deg of LF position, 0.5 m/s, 0.5 m/s, 1 deg/s, the bias's
    and the WF states' stationary spread."""
    import scipy.linalg  # (here: `import estimators` need not load it)

    p = model.params
    wave = scipy.linalg.solve_continuous_lyapunov(p.A_w, -p.E_w @ p.E_w.T)
    P0 = np.zeros((15, 15))
    P0[:6, :6] = np.diag([25.0, 25.0, (5 * DEG) ** 2, 0.25, 0.25, DEG**2])
    P0[6:9, 6:9] = np.diag(np.array(p.sigma_b) ** 2)
    P0[9:, 9:] = wave
    return (P0 + P0.T) / 2
