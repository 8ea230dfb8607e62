"""The nominal filter's innovations, and how a candidate term would change them.

The prediction-error view of a mismatch: the nominal extended Kalman filter's innovations
``nu_k`` are white when the model is right. A missing term ``c * w(x, u)`` in the state
equations (or ``c * v`` on the measured channels) changes them, to first order, *linearly* in
``c``: ``nu_k(c) = nu_k - c * g_k``. The sensitivity ``g`` is the filter's own response to the
term, propagated through its time-varying closed loop

    d_{k+1} = Phi_k (I - K_k H_k) d_k - Phi_k K_k v_k + Gamma_k w_k,    g_k = H_k d_k + v_k

(``Phi_k``: the transition, ``K_k``: the gain, ``Gamma_k``: the held-input integral over one
step). So a term in an unmeasured state's equation shows in the channels it drives, the random
sea stays in the filter's process noise instead of swamping the comparison, and every
hypothesis is a least-squares fit of ``g`` to ``nu``: this is the prediction-error method
(Ljung) linearised about the nominal filter. Everything is whitened by the innovation
covariance ``S_k``, so a unit of ``nu`` means the same on every channel.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import linalg, ndimage, signal

from ..ekf import ExtendedKalmanFilter, FilterResult

FloatArray = NDArray[np.float64]
#: Order of the autoregressive model of each channel's innovations: the unmodelled sea is
#: coloured, so the filter's innovations are too; their prediction-error filter whitens them.
AR_ORDER = 20
#: The colour is the innovation spectrum's running median over this many Welch bins (0.12
#: rad/s each at 10 Hz): broad sea colour is whitened, a narrow peak (an unmodelled
#: oscillation, ``zeta`` up to about 0.1) is a model error and stays.
BACKGROUND_BINS = 11


def _ar_fit(x: FloatArray, order: int, segment: int = 512) -> FloatArray:
    """The prediction-error filter ``[1, -a_1, ..., -a_p]`` of the smooth background of
    ``x``'s spectrum (Yule-Walker on the autocovariance of the running-median Welch spectrum,
    about the mean: a constant or a narrow peak is a model error to explain, not colour)."""
    _, psd = signal.welch(x - x.mean(), nperseg=min(segment, len(x) // 4))
    background = np.exp(ndimage.median_filter(np.log(psd + 1e-300), BACKGROUND_BINS,
                                              mode="nearest"))
    acov = np.fft.irfft(background)[:order + 1]
    a = linalg.solve_toeplitz(acov[:order], acov[1:])
    return np.concatenate([[1.0], -a])


def _moving_average(a: FloatArray, x: FloatArray) -> FloatArray:
    """``sum_i a_i x_{k-i}`` along axis 0 from rest (one lfilter call: faster than a sum per
    lag once the AR filter is long)."""
    return signal.lfilter(a, [1.0], x, axis=0)


@dataclass
class Innovations:
    """Whitened innovations ``nu`` ``(T, m)`` and the filter's closed loop.

    :param M: ``Phi_k (I - K_k H_k)`` ``(T - 1, n, n)``.
    :param Gamma: one step's response to a held unit state derivative ``(T - 1, n, n)``, s.
    :param PhiK: ``Phi_k K_k`` ``(T - 1, n, m)``.
    :param H: whitened output matrices ``L_k^-1 H_k`` ``(T, m, n)`` (``S_k = L_k L_k'``).
    :param L_inv: ``L_k^-1`` ``(T, m, m)``.
    :param K, H_raw, Phi: gains ``(T, n, m)``, output matrices ``(T, m, n)``, transitions.
    :param C: the smoother's gains ``P_k Phi_k' P_pred_{k+1}^-1`` ``(T - 1, n, n)``.
    :param ar: each channel's prediction-error filter (see ``AR_ORDER``), or None.
    :param n_model: the model's states: the first ``n_model`` of the filter's ``n`` (the rest
        are its forcing states, which candidate terms do not enter).
    """

    nu: FloatArray
    M: FloatArray
    Gamma: FloatArray
    PhiK: FloatArray
    H: FloatArray
    L_inv: FloatArray
    K: FloatArray
    H_raw: FloatArray
    Phi: FloatArray
    C: FloatArray
    ar: FloatArray | None = None
    n_model: int | None = None

    @classmethod
    def from_filter(cls, ekf: ExtendedKalmanFilter, run: FilterResult, u: FloatArray,
                    n_model: int | None = None) -> Innovations:
        """From a single filter's offline run (``run.x_pred`` etc. with batch size 1) on the
        inputs ``u`` ``(T, n_u)``, whose first ``n_model`` states (default: all) are the
        model's."""
        n = len(run.state_names)
        x_pred, P_pred = run.x_pred[:, 0], run.P_pred[:, 0]
        H, _ = ekf._measurement_jacobian(x_pred)
        H = H[:, :, :n]
        S = H @ P_pred @ H.transpose(0, 2, 1) + ekf.R
        L_inv = np.linalg.inv(np.linalg.cholesky(S))
        K = P_pred @ H.transpose(0, 2, 1) @ np.linalg.inv(S)
        Phi = run.transition[:, 0, :n, :n]
        IKH = np.eye(n) - K[:-1] @ H[:-1]
        nu = (L_inv @ run.innovation[:, 0, :, None])[:, :, 0]
        ar = np.stack([_ar_fit(nu[:, j], AR_ORDER) for j in range(nu.shape[1])]) \
            if AR_ORDER else None
        P = run.P[:, 0, :n, :n]
        C = np.linalg.solve(P_pred[1:], Phi @ P[:-1]).transpose(0, 2, 1)
        # exact for a stiff mode: the trapezoid dt (Phi + I) / 2 is 2.4x too large for the
        # hydrofoil's pitch, and a pitch damping fitted through it came out at 31 % of the truth
        Gamma = ekf.held_input_response(run.x[:-1, 0], u[:-1])
        out = cls(nu=nu, M=Phi @ IKH, Gamma=Gamma, PhiK=Phi @ K[:-1],
                  H=L_inv @ H, L_inv=L_inv, K=K, H_raw=H, Phi=Phi, C=C, ar=ar,
                  n_model=n if n_model is None else n_model)
        out.nu = out._whiten(nu)
        return out

    def _whiten(self, x: FloatArray) -> FloatArray:
        """Each channel through its prediction-error filter (axis 0 is time)."""
        if self.ar is None:
            return x
        out = np.empty_like(x)
        for j, a in enumerate(self.ar):
            out[:, j] = _moving_average(a, x[:, j])
        return out

    @property
    def shape(self) -> tuple[int, int, int]:
        """``(T, m, n)``: steps, channels, the filter's states."""
        return self.nu.shape[0], self.nu.shape[1], self.M.shape[1]

    def _pad(self, w: FloatArray) -> FloatArray:
        """A term in the model's equations ``(T, n_model, ...)`` as one in the filter's."""
        extra = self.M.shape[1] - w.shape[1]
        return np.pad(w, [(0, 0), (0, extra)] + [(0, 0)] * (w.ndim - 2)) if extra else w

    def smoothed_shift(self, w: FloatArray | None = None,
                       v: FloatArray | None = None) -> FloatArray:
        """How the smoothed states move ``(T, n)`` when the model gains the term ``w``
        ``(T, n)`` (state derivatives) and the channels the offset ``v`` ``(T, m)``: the
        filter's shift (as in :meth:`response`), then the Rauch-Tung-Striebel recursion;
        the model's states only ``(T, n_model)``."""
        T, m, n = self.shape
        w = np.zeros((T, n)) if w is None else self._pad(w)
        v = np.zeros((T, m)) if v is None else v
        before, after = np.zeros((T, n)), np.zeros((T, n))
        for k in range(T):
            after[k] = before[k] - self.K[k] @ (self.H_raw[k] @ before[k] + v[k])
            if k < T - 1:
                before[k + 1] = self.Phi[k] @ after[k] + self.Gamma[k] @ w[k]
        smoothed = after.copy()
        for k in range(T - 2, -1, -1):
            smoothed[k] = after[k] + self.C[k] @ (smoothed[k + 1] - before[k + 1])
        return smoothed[:, :self.n_model]

    def response(self, w: FloatArray | None = None, v: FloatArray | None = None) -> FloatArray:
        """Whitened innovation change per unit coefficient ``(T, m, R)`` of ``R`` candidate
        terms: ``w`` ``(T, n, R)`` added to the state derivatives (state units per second),
        ``v`` ``(T, m, R)`` added to the measured channels (channel units)."""
        T, m, n = self.shape
        R = (w if w is not None else v).shape[2]  # type: ignore[union-attr]
        drive = np.zeros((T - 1, n, R))
        if w is not None:
            drive += self.Gamma @ self._pad(w)[:-1]
        if v is not None:
            drive -= self.PhiK @ v[:-1]
        d = np.zeros((T, n, R))
        for k in range(T - 1):
            d[k + 1] = self.M[k] @ d[k] + drive[k]
        g = self.H @ d
        if v is not None:
            g += self.L_inv @ v
        return self._whiten(g)
