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

The recursions run compiled (:func:`response_loop`, :func:`shift_loop`, :func:`fir`): a search
asks for the response of hundreds of candidate terms over the whole record.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import linalg, ndimage, signal

from marine_envs.compiled import jit

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

    def __post_init__(self) -> None:
        # the one layout the loops are compiled for (the filter's arrays are views: strided,
        # broadcast, read-only)
        for name in ("M", "Gamma", "PhiK", "H", "L_inv", "K", "H_raw", "Phi", "C"):
            setattr(self, name, c_array(getattr(self, name)))

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
        """Each channel through its prediction-error filter (axis 0 is time, axis 1 the
        channel; ``(T, m)`` or ``(T, m, R)``)."""
        if self.ar is None:
            return x
        out = c_array(x.reshape(x.shape[0], x.shape[1], -1), copy=True)
        fir(c_array(self.ar), out)
        return out.reshape(x.shape)

    def _taps(self) -> FloatArray:
        """The prediction-error filters ``(m, p + 1)``; a unit tap without them."""
        return np.ones((self.nu.shape[1], 1)) if self.ar is None else c_array(self.ar)

    @property
    def shape(self) -> tuple[int, int, int]:
        """``(T, m, n)``: steps, channels, the filter's states."""
        return self.nu.shape[0], self.nu.shape[1], self.M.shape[1]

    def smoothed_shift(self, w: FloatArray | None = None,
                       v: FloatArray | None = None) -> FloatArray:
        """How the smoothed states move ``(T, n)`` when the model gains the term ``w``
        ``(T, n)`` (state derivatives) and the channels the offset ``v`` ``(T, m)``: the
        filter's shift (as in :meth:`response`), then the Rauch-Tung-Striebel recursion;
        the model's states only ``(T, n_model)``."""
        T, m, n = self.shape
        w = np.zeros((T, 0)) if w is None else c_array(w)
        v = np.zeros((T, m)) if v is None else c_array(v)
        smoothed = np.empty((T, n))
        shift_loop(self.K, self.H_raw, self.Phi, self.Gamma, self.C, w, v, smoothed)
        return smoothed[:, :self.n_model]

    def response(self, w: FloatArray | None = None, v: FloatArray | None = None) -> FloatArray:
        """Whitened innovation change per unit coefficient ``(T, m, R)`` of ``R`` candidate
        terms: ``w`` ``(T, n, R)`` added to the state derivatives (state units per second),
        ``v`` ``(T, m, R)`` added to the measured channels (channel units)."""
        T, m, _ = self.shape
        R = (w if w is not None else v).shape[2]  # type: ignore[union-attr]
        w = np.zeros((T, 0, R)) if w is None else c_array(w)
        v = np.zeros((T, 0, R)) if v is None else c_array(v)
        out = np.empty((T, m, R))
        response_loop(self.M, self.Gamma, self.PhiK, self.H, self.L_inv, w, v, self._taps(),
                      out)
        return out


def c_array(a: FloatArray, copy: bool = False) -> FloatArray:
    """``a`` as a writable C-contiguous float64 array (a copy if it is not one, or asked): the
    one layout the compiled loops are compiled for."""
    usable = a.dtype == np.float64 and a.flags.c_contiguous and a.flags.writeable
    return a if usable and not copy else np.array(a, dtype=np.float64, order="C")


# -- the compiled loops ---------------------------------------------------------------------------
@jit
def response_loop(M, Gamma, PhiK, H, L_inv, w, v, ar, out):
    """:meth:`Innovations.response` written to ``out`` ``(T, m, R)``: ``d_{k+1} = M_k d_k +
    Gamma_k w_k - PhiK_k v_k`` from ``d_0 = 0``, ``g_k = H_k d_k + L_inv_k v_k``, each channel
    through its filter ``ar`` (:func:`fir`; the last ``g`` kept in a ring, so that ``out`` is
    written once). ``w`` ``(T, n_w, R)`` enters the first ``n_w`` states; ``v`` ``(T, m, R)``,
    or ``(T, 0, R)`` for none. Only the states a term enters anywhere are read (a candidate
    enters one equation: the rest of ``Gamma_k w_k`` is zeros)."""
    T, m, R = out.shape
    n, n_v, taps = M.shape[1], v.shape[1], ar.shape[1]
    entered = _entered(w)
    d, ahead = np.zeros((n, R)), np.empty((n, R))
    ring = np.empty((taps, m, R))
    for k in range(T):
        for j in range(m):
            g = ring[k % taps, j]
            g[:] = 0.0
            for i in range(n):
                _axpy(H[k, j, i], d[i], g)
            for c in range(n_v):
                _axpy(L_inv[k, j, c], v[k, c], g)
            y = out[k, j]
            y[:] = 0.0
            for i in range(min(taps, k + 1)):
                _axpy(ar[j, i], ring[(k - i) % taps, j], y)
        if k == T - 1:
            break
        for i in range(n):
            row = ahead[i]
            row[:] = 0.0
            for ll in range(n):
                _axpy(M[k, i, ll], d[ll], row)
            for ll in entered:
                _axpy(Gamma[k, i, ll], w[k, ll], row)
            for c in range(n_v):
                _axpy(-PhiK[k, i, c], v[k, c], row)
        d, ahead = ahead, d


@jit
def shift_loop(K, H, Phi, Gamma, C, w, v, out):
    """:meth:`Innovations.smoothed_shift` of every filter state written to ``out`` ``(T, n)``:
    the filter's shift ``a_k = b_k - K_k (H_k b_k + v_k)``, ``b_{k+1} = Phi_k a_k + Gamma_k
    w_k`` from ``b_0 = 0``, then ``s_k = a_k + C_k (s_{k+1} - b_{k+1})``. ``w`` ``(T, n_w)``
    enters the first ``n_w`` states, ``v`` ``(T, m)``."""
    T, n = out.shape
    m, n_w = H.shape[1], w.shape[1]
    before, after = np.zeros((T, n)), np.empty((T, n))
    seen, step = np.empty(m), np.empty(n)
    for k in range(T):
        for j in range(m):
            seen[j] = v[k, j] + _dot(H[k, j], before[k])
        for i in range(n):
            after[k, i] = before[k, i] - _dot(K[k, i], seen)
        if k < T - 1:
            for i in range(n):
                before[k + 1, i] = _dot(Phi[k, i], after[k]) + _dot(Gamma[k, i, :n_w], w[k])
    out[T - 1] = after[T - 1]
    for k in range(T - 2, -1, -1):
        for i in range(n):
            step[i] = out[k + 1, i] - before[k + 1, i]
        for i in range(n):
            out[k, i] = after[k, i] + _dot(C[k, i], step)


@jit
def fir(a, x):
    """Each channel ``j`` of ``x`` ``(T, m, R)`` through its filter ``a[j]``, in place:
    ``x_k <- sum_i a_ji x_{k-i}`` from rest (latest sample first, so the older ones it reads
    are still the inputs)."""
    T, m, R = x.shape
    total = np.empty(R)
    for k in range(T - 1, -1, -1):
        for j in range(m):
            total[:] = 0.0
            for i in range(min(a.shape[1], k + 1)):
                _axpy(a[j, i], x[k - i, j], total)
            x[k, j] = total


@jit
def _entered(w):
    """The states ``l`` whose ``w[:, l, :]`` ``(T, n_w, R)`` is not all zeros."""
    T, n_w, R = w.shape
    entered = np.zeros(n_w, dtype=np.bool_)
    for k in range(T):
        for ll in range(n_w):
            if not entered[ll]:
                for r in range(R):
                    if w[k, ll, r] != 0.0:
                        entered[ll] = True
                        break
    return np.flatnonzero(entered)


@jit
def _axpy(c, x, y):
    """``y += c x`` (1-D)."""
    for r in range(y.size):
        y[r] += c * x[r]


@jit
def _dot(a, b):
    """``sum a_i b_i`` (1-D)."""
    total = 0.0
    for i in range(a.size):
        total += a[i] * b[i]
    return total
