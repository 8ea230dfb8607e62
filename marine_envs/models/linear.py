"""Linear-system numerics, written once: zero-order-hold discretisation and the LQR designs
(Riccati solutions) shared by the LQR policy (:mod:`agents.lqr`), the environments' exact
step, the filters and the synthetic recordings of the diagnosis.

Conventions (as python-control's ``lqr``/``dlqr``): ``u = u_ref - K (x - x_ref)``; the
continuous design minimises ``integral x'Qx + u'Ru dt`` for ``x_dot = A x + B u``; the discrete
design minimises ``sum_k x_k'Q x_k + u_k'R u_k`` for the zero-order-hold (ZOH) discretisation of
that model with period ``dt``. Integral action augments the state with ``z`` per integrated state
``i``: ``z_dot = x_i - x_ref_i`` (continuous) or ``z_{k+1} = z_k + dt (x_i - x_ref_i)``
(discrete). Inputs are checked here, at the boundary: a wrong shape, a non-finite entry or a
weight that is not (semi-)definite is a ``ValueError`` naming it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .base import FloatArray


class LQRSolution(NamedTuple):
    """Result of an LQR design; unpacks as ``K, P, poles`` (python-control's ``K, S, E``).

    :param K: gain of ``u = -K x``, ``(n_u, n_x)``.
    :param P: the Riccati solution (cost-to-go ``x'Px``), ``(n_x, n_x)``.
    :param poles: closed-loop eigenvalues: of ``A - BK`` (1/s) for a continuous design, of
        ``Ad - Bd K`` (z-plane, dimensionless) for a discrete one.
    """

    K: FloatArray
    P: FloatArray
    poles: NDArray[np.complex128]


# -- designs -------------------------------------------------------------------------------------
def zoh(A: ArrayLike, B: ArrayLike, dt: float) -> tuple[FloatArray, FloatArray]:
    """Zero-order-hold discretisation ``(Phi, Gamma)`` of ``x_dot = A x + B w`` with period
    ``dt`` (s): ``Phi = exp(A dt)``, ``Gamma = int_0^dt exp(A s) ds B``, exact for ``w`` held
    over each period."""
    import scipy.linalg  # (here, not at import: it takes 0.1 s)

    A, B = check_matrix("A", A), check_matrix("B", B)
    dt = check_period(dt)
    n, m = B.shape
    if A.shape != (n, n):
        raise ValueError(f"shapes do not match: A {A.shape}, B {B.shape}")
    block = np.zeros((n + m, n + m))
    block[:n, :n], block[:n, n:] = A, B
    phi = scipy.linalg.expm(block * dt)
    return phi[:n, :n], phi[:n, n:]


def lqr(A: ArrayLike, B: ArrayLike, Q: ArrayLike, R: ArrayLike,
        dt: float | None = None) -> LQRSolution:
    """LQR of ``x_dot = A x + B u``: continuous if ``dt`` is None, else the discrete LQR of its
    ZOH discretisation with period ``dt`` (s).

    :param A, B: continuous-time model, ``(n, n)`` and ``(n, m)``.
    :param Q, R: state and input weights, ``(n, n)`` symmetric >= 0 and ``(m, m)`` symmetric > 0.
    :raises ValueError: shapes that do not match, non-finite entries, Q not positive
        semi-definite, R not positive definite, ``(A, B)`` not stabilisable, or a marginal mode
        that Q does not see (no stabilising Riccati solution); the message names the mode.
    """
    A, B, Q, R = _check_design(A, B, Q, R)
    if dt is None:
        return _solve(A, B, Q, R, discrete=False)
    Ad, Bd = zoh(A, B, dt)
    return _solve(Ad, Bd, Q, R, discrete=True)


def dlqr(Ad: ArrayLike, Bd: ArrayLike, Q: ArrayLike, R: ArrayLike,
         discount: float = 1.0) -> LQRSolution:
    """Discrete LQR of ``x_{k+1} = Ad x_k + Bd u_k`` minimising ``sum_k g^k (x_k'Q x_k +
    u_k'R u_k)`` with the discount ``g = discount`` (1: the undiscounted design). Below one, a
    mode on the unit circle that the inputs cannot move no longer prevents a design; the closed
    loop is then only guaranteed to have its poles inside ``|z| < 1 / sqrt(g)``.

    :raises ValueError: as :func:`lqr`; also a discount outside (0, 1].
    """
    if not (isinstance(discount, int | float) and 0 < discount <= 1):
        raise ValueError(f"discount={discount!r} is invalid: 0 < discount <= 1")
    return _solve(*_check_design(Ad, Bd, Q, R), discrete=True, discount=float(discount))


def dlqr_gain(Ad: ArrayLike, Bd: ArrayLike, q: ArrayLike, r: ArrayLike,
              discount: float = 0.9999) -> FloatArray:
    """The gain ``K`` ``(n_u, n)`` of :func:`dlqr` with diagonal weights ``q`` ``(n,)`` and
    ``r`` ``(n_u,)``, designed on the states that are weighted or move another state (the
    others, e.g. a position only a heading's cost ignores, get no gain and would leave the
    Riccati equation without a solution); the discount (default just below one) lets marginal
    modes the inputs cannot move (a bias, a random-walk disturbance) pass.

    :raises ValueError: as :func:`dlqr`.
    """
    Ad, Bd = check_matrix("Ad", Ad), check_matrix("Bd", Bd)
    q, r = np.asarray(q, dtype=float), np.asarray(r, dtype=float)
    n = Ad.shape[0]
    moved = np.any(Ad - np.eye(n) != 0, axis=0)
    keep = np.flatnonzero((q != 0) | moved)
    K = np.zeros((Bd.shape[1], n))
    K[:, keep] = dlqr(Ad[np.ix_(keep, keep)], Bd[keep], np.diag(q[keep]), np.diag(r),
                      discount=discount).K
    return K


def dlqe(F: ArrayLike, H: ArrayLike, Q: ArrayLike,
         R: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """The steady-state Kalman filter of ``x_{k+1} = F x_k + w``, ``y_k = H x_k + v`` with
    ``w ~ N(0, Q)``, ``v ~ N(0, R)``: the stationary predicted and updated covariances
    ``(P_pred, P_upd)``, by duality with :func:`dlqr` (its Riccati equation with
    ``(A, B) = (F', H')``; python-control's ``dlqe``).

    :raises ValueError: as :func:`dlqr`, read with ``A = F'``, ``B = H'``: a mode that
        ``(F', H')`` cannot stabilise is one that the measurements ``H`` do not detect.
    """
    P_pred = dlqr(np.transpose(F), np.transpose(H), Q, R).P
    H, R = check_matrix("H", H), check_matrix("R", R)
    S = H @ P_pred @ H.T + R
    P_upd = P_pred - P_pred @ H.T @ np.linalg.solve(S, H @ P_pred)
    return P_pred, (P_upd + P_upd.T) / 2


def lqr_gain(A: ArrayLike, B: ArrayLike, Q: ArrayLike, R: ArrayLike,
             dt: float | None = None) -> FloatArray:
    """State-feedback gain K of ``u = -K x`` (see :func:`lqr`, whose ``K`` it is)."""
    return lqr(A, B, Q, R, dt).K


def lqr_integral(A: ArrayLike, B: ArrayLike, Q: ArrayLike, R: ArrayLike,
                 integrated: Sequence[int], weights: ArrayLike,
                 dt: float | None = None) -> LQRSolution:
    """LQR with integral action on states ``integrated``.

    The model is augmented with ``z_dot = x_i`` (continuous, ``dt`` None) or, for the ZOH model,
    ``z_{k+1} = z_k + dt x_i`` (discrete), in deviation variables; the augmented state
    ``[x, z]`` is weighted by ``blockdiag(Q, diag(weights))``.

    :param integrated: indices of the integrated states (each once).
    :param weights: LQR weight of each integral state, > 0 (units 1/(state unit * s)^2).
    :return: the augmented solution; ``K[:, :n]`` acts on ``x``, ``K[:, n:]`` on ``z``.
    :raises ValueError: as :func:`lqr`; also bad indices or weights, or a pair that integral
        action makes unstabilisable (an integrated state the inputs cannot hold away from its
        equilibrium, i.e. a transmission zero at s = 0).
    """
    import scipy.linalg  # (here, not at import: it takes 0.1 s)

    A, B, Q, R = _check_design(A, B, Q, R)
    n, m = B.shape
    idx = np.asarray(integrated, dtype=int).reshape(-1)
    w = np.asarray(weights, dtype=float).reshape(-1)
    if idx.size == 0 or len(set(idx.tolist())) != idx.size or idx.min() < 0 or idx.max() >= n:
        raise ValueError(f"integrated={idx.tolist()} is invalid: distinct state indices in "
                         f"[0, {n})")
    if w.shape != idx.shape or not np.all(np.isfinite(w) & (w > 0)):
        raise ValueError(f"weights={w.tolist()} is invalid: one finite weight > 0 per integrated "
                         "state")
    C = np.zeros((idx.size, n))
    C[np.arange(idx.size), idx] = 1.0
    n_z = idx.size
    # the integrators' modes at 0 are reachable only if the inputs can hold every integrated
    # state at any value in steady state: no transmission zero at s = 0
    if np.linalg.matrix_rank(np.block([[A, B], [C, np.zeros((n_z, m))]])) < n + n_z:
        raise ValueError(f"integral action on states {idx.tolist()} is not stabilisable: the "
                         f"{m} input(s) cannot hold them at arbitrary values in steady state "
                         "(rank [[A, B], [C, 0]] < n + n_z; more integrated states than inputs, "
                         "or an integrated state the inputs do not move)")
    Q_aug = scipy.linalg.block_diag(Q, np.diag(w))
    B_aug = np.vstack([B, np.zeros((n_z, m))])
    if dt is None:
        A_aug = np.block([[A, np.zeros((n, n_z))], [C, np.zeros((n_z, n_z))]])
        return _solve(A_aug, B_aug, Q_aug, R, discrete=False)
    Ad, Bd = zoh(A, B, dt)
    # the integrator is advanced with the error of the period's start, as the policy does
    A_aug = np.block([[Ad, np.zeros((n, n_z))], [dt * C, np.eye(n_z)]])
    B_aug[:n] = Bd
    return _solve(A_aug, B_aug, Q_aug, R, discrete=True)


def check_matrix(name: str, value: ArrayLike) -> FloatArray:
    """``value`` as a finite float matrix; :raises ValueError: naming ``name``."""
    a = np.atleast_2d(np.asarray(value, dtype=float))
    if a.ndim != 2:
        raise ValueError(f"{name} must be a matrix, got shape {a.shape}")
    if not np.isfinite(a).all():
        raise ValueError(f"{name} has non-finite entries")
    return a


def check_period(dt: Any) -> float:
    """``dt`` as a period > 0 s; :raises ValueError: otherwise."""
    if not (isinstance(dt, int | float | np.floating | np.integer) and np.isfinite(dt)
            and dt > 0):
        raise ValueError(f"dt={dt!r} is invalid: a period > 0 s")
    return float(dt)


def _check_design(A: ArrayLike, B: ArrayLike, Q: ArrayLike,
                  R: ArrayLike) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """The four matrices as float arrays, or a ValueError naming the one that is wrong."""
    A, B, Q, R = (check_matrix(k, v) for k, v in zip("ABQR", (A, B, Q, R), strict=True))
    n, m = B.shape
    if A.shape != (n, n) or Q.shape != (n, n) or R.shape != (m, m):
        raise ValueError(f"shapes do not match: A {A.shape}, B {B.shape}, Q {Q.shape}, "
                         f"R {R.shape}; expected ({n}, {n}), (n, m), ({n}, {n}), ({m}, {m})")
    for name, W in (("Q", Q), ("R", R)):
        scale = max(1.0, np.abs(W).max())
        if not np.allclose(W, W.T, rtol=0, atol=1e-12 * scale):
            raise ValueError(f"{name} must be symmetric")
    lowest = np.linalg.eigvalsh(Q).min()
    if lowest < -1e-12 * max(1.0, np.abs(Q).max()):
        raise ValueError(f"Q must be positive semi-definite (smallest eigenvalue {lowest:.3g})")
    lowest = np.linalg.eigvalsh(R).min()
    if lowest <= 0:
        raise ValueError(f"R must be positive definite (smallest eigenvalue {lowest:.3g})")
    return A, B, Q, R


def _solve(A: FloatArray, B: FloatArray, Q: FloatArray, R: FloatArray,
           discrete: bool, discount: float = 1.0) -> LQRSolution:
    """Solve the Riccati equation; turn scipy's failures into a ValueError that says why."""
    import scipy.linalg  # (here, not at import: it takes 0.1 s)

    try:
        if discrete:
            # sum_k g^k (x'Qx + u'Ru) is the undiscounted cost of (sqrt(g) A, sqrt(g) B)
            root = math.sqrt(discount)
            P = scipy.linalg.solve_discrete_are(root * A, root * B, Q, R)
            K = np.linalg.solve(R / discount + B.T @ P @ B, B.T @ P @ A)
        else:
            P = scipy.linalg.solve_continuous_are(A, B, Q, R)
            K = np.linalg.solve(R, B.T @ P)
    except (np.linalg.LinAlgError, ValueError) as error:
        raise ValueError(_why_no_solution(A, B, Q, discrete) + f" (scipy: {error})") from None
    poles = np.linalg.eigvals(A - B @ K)
    # scipy may return a finite but non-stabilising solution (e.g. an unweighted integrator)
    stable = (np.abs(poles).max() * math.sqrt(discount) < 1 if discrete
              else poles.real.max() < 0)
    if not (np.isfinite(K).all() and stable):
        raise ValueError(_why_no_solution(A, B, Q, discrete)
                         + f" (closed-loop poles {np.round(poles, 6).tolist()})")
    return LQRSolution(K, (P + P.T) / 2, poles)


def _why_no_solution(A: FloatArray, B: FloatArray, Q: FloatArray, discrete: bool) -> str:
    """Popov-Belevitch-Hautus tests on the modes that need stabilising, as a message."""
    n = A.shape[0]
    scale = max(1.0, np.abs(A).max(), np.abs(B).max(), np.abs(Q).max())
    tol = 1e-8 * scale
    for lam in np.linalg.eigvals(A):
        unstable = abs(lam) >= 1 - 1e-9 if discrete else lam.real >= -1e-9 * scale
        if not unstable:
            continue
        shifted = A - lam * np.eye(n)
        # an unreachable mode: w' [A - lam I, B] = 0
        u_, s, _ = np.linalg.svd(np.hstack([shifted, B]))
        if s[-1] < tol:
            where = "on or outside the unit circle" if discrete else "unstable or marginal"
            return (f"(A, B) is not stabilisable: the mode at {_fmt(lam)} (in states "
                    f"{_mode_states(u_[:, -1])}) is {where} and the inputs cannot move it")
        marginal = abs(abs(lam) - 1) < 1e-9 if discrete else abs(lam.real) <= 1e-9 * scale
        if marginal:
            # a marginal mode Q does not see: [A - lam I; Q] v = 0
            _, s, vh = np.linalg.svd(np.vstack([shifted, Q]))
            if s[-1] < tol:
                states = _mode_states(vh[-1].conj())
                return (f"no stabilising LQR solution: the marginal mode at {_fmt(lam)} (in "
                        f"states {states}) is not weighted by Q; weigh it or leave the state out")
    return "no stabilising LQR solution (ill-conditioned or not stabilisable model)"


def _mode_states(vector: NDArray[np.complex128]) -> list[int]:
    magnitude = np.abs(vector)
    return np.flatnonzero(magnitude > 0.3 * magnitude.max()).tolist()


def _fmt(lam: complex) -> str:
    return f"{lam.real:.4g}" if abs(lam.imag) < 1e-12 else f"{lam:.4g}"
