"""Seed 000's proportional-derivative (PD) observer on quantized network data (MODELS.md 1.3-1.6).

The method, in the seed's symbols (MODELS.md 1.5 gives the reconstruction):

1. **Standard form.** ``x = T x_c``, ``y = S y_c`` put the disturbance-hit, directly measured
   states first: ``x = [x1; x2]``, ``D = [D1; 0]`` with ``D1`` invertible, ``y1 = x1``,
   ``y2 = C2 x`` (:func:`standard_form`, :func:`usv_standard_form`).
2. **Network.** The sensor sends ``q(e1)`` (``e1 = x_hat1 - y1``, zooming quantizer with
   ``mu1 = 2 k ||e1|| / sqrt(m1)``, ``mu1`` sent along) and ``q(y2)`` (static step ``mu2``).
3. **Augmented descriptor system** ``x_bar = [x; eps]``, ``eps = q(y2) - y2``, and the matrix
   ``M = (E_bar + R C_bar2)^-1`` (:func:`augment`).
4. **PD observer** ``xi' = As xi + M B_bar u + N q(y2) + M D_bar us1``,
   ``x_bar_hat = xi + R q(y2)``, ``As = M A_bar - Ls C_bar2``, ``N = As R + Ls``, with the
   disturbance-rejecting input ``us1 = -rho D1' P1 q(e1) / (||D1' P1 q(e1)|| + delta)`` (the seed
   writes ``P1 q(e1)``; ``D1 = I`` for the USV).
5. **LMI** (:func:`design_pd_observer`): ``P = blkdiag(P1, P2) > 0``, ``Y`` with
   ``He(P M A_bar - Y C_bar2) + 2 alpha P < 0``; ``Ls = P^-1 Y``. The block-diagonal ``P`` is the
   matching condition ``P M D_bar = E1' P1 D1`` that turns the disturbance term into
   ``-2 e1' P1 D1 (d - us1) <= 2 rho delta``.

Findings the code documents (numbers in the reproduction ``usv-quantized-observer``):

* The error obeys ``e_bar' = As e_bar + E1'(d - us1) + R eps``: the quantization error ``eps``
  does not cancel, so the seed's feasibility-only design leaves an error that grows with ``mu2``.
* For the USV the largest decay rate is ``alpha -> 1/Tv = 0.1`` (not attained): with the matching
  condition the ``x2`` block must satisfy a Lyapunov inequality on its own, and the sway mode
  ``v' = -v/Tv`` is unobservable inside it (it reaches ``y2`` only through ``x1 = [r, p]``).
* The input ``us1`` slides ``x_hat1`` onto ``y1``: it absorbs the sway error's footprint in
  ``r`` and ``p`` as if it were wave disturbance, which it cannot be told apart from.
* ``objective="decoupled"`` adds linear constraints to the same LMI (``Y`` rows and ``P``
  couplings of the unmeasured states set to zero, so their rows of ``Ls`` vanish): the gain from
  ``eps`` to their error is then exactly zero. For the USV that is the physically right answer:
  the sway mode is autonomous (``v' = (-v + Kdv delta)/Tv``) and an invariant zero of the
  disturbance channel, so no measured channel says more about ``v`` than the model does when
  ``d`` is unknown; the ``v`` error decays as ``exp(-t/Tv)`` whatever ``mu2`` and ``d``. (A
  bounded-real "minimise the gain" objective was tried first: it reaches a small gain only as the
  condition number of ``P`` grows without bound, which also makes ``P1``, and so ``us1``,
  lopsided; the exact constraint has neither problem.)
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from collections.abc import Sequence
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from marine_envs.models.usv import USVModel
from marine_envs.sensors import ZoomingQuantizer, quantize

from .base import FloatArray
from .luenberger import HeldInputObserver, check_positive, check_steps, steps_per_row

Objective = Literal["feasibility", "decoupled"]

#: Solvers used by default; the first one's certificate is used, the others cross-check it.
DEFAULT_SOLVERS: tuple[str, ...] = ("CLARABEL", "SCS")


# -- 1. standard form --------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True, eq=False)  # arrays: compare fields explicitly
class StandardForm:
    """A plant ``x_c' = A_c x_c + B_c u + D_c d``, ``y_c = C_c x_c`` and its standard form.

    ``x = T x_c = [x1; x2]`` (``x1``: the ``n1`` states the disturbance enters, measured
    directly), ``y = S y_c = [y1; y2]`` with ``y1 = x1``. Then ``A = T A_c T^-1``, ``B = T B_c``,
    ``D = T D_c = [D1; 0]``, ``C = S C_c T^-1 = [C1; C2]`` with ``C1 = [I 0]``; ``C2`` is the full
    width ``(p - n1, n)`` block (MODELS.md 1.3's ``C2full``).
    """

    A_c: FloatArray
    B_c: FloatArray
    D_c: FloatArray
    C_c: FloatArray
    T: FloatArray
    S: FloatArray
    A: FloatArray
    B: FloatArray
    D: FloatArray
    C: FloatArray
    C1: FloatArray
    C2: FloatArray
    D1: FloatArray
    n1: int
    state_names: tuple[str, ...]  #: original state order (of ``x_c``)
    measurement_names: tuple[str, ...]  #: original channel order (of ``y_c``)

    @property
    def standard_state_names(self) -> tuple[str, ...]:
        """Names of ``x = T x_c``."""
        return tuple(self.state_names[int(np.argmax(row))] for row in np.abs(self.T))


def standard_form(A_c: ArrayLike, B_c: ArrayLike, D_c: ArrayLike, C_c: ArrayLike,
                  state_names: Sequence[str] | None = None,
                  measurement_names: Sequence[str] | None = None) -> StandardForm:
    """Reorder states and channels into the seed's standard form (permutations ``T``, ``S``).

    :param A_c: ``(n, n)`` state matrix, 1/s.
    :param B_c: ``(n, n_u)`` input matrix.
    :param D_c: ``(n, n1)`` disturbance matrix; it must enter exactly ``n1`` states.
    :param C_c: ``(p, n)`` output matrix whose rows are rows of the identity; every state
        ``D_c`` enters must be measured.
    :raises ValueError: the plant cannot be put into the standard form, saying why.
    """
    A_c, B_c, D_c, C_c = (np.atleast_2d(np.asarray(a, dtype=float)) for a in (A_c, B_c, D_c, C_c))
    n, n1 = A_c.shape[0], D_c.shape[1]
    if A_c.shape != (n, n) or B_c.shape[0] != n or D_c.shape[0] != n or C_c.shape[1] != n:
        raise ValueError(f"shapes A_c {A_c.shape}, B_c {B_c.shape}, D_c {D_c.shape}, C_c "
                         f"{C_c.shape} do not fit together (B_c and D_c need n rows)")
    names = tuple(state_names or [f"x{i}" for i in range(n)])
    channels = tuple(measurement_names or [f"y{i}" for i in range(C_c.shape[0])])
    hit = [int(i) for i in np.flatnonzero(np.abs(D_c).sum(axis=1))]
    if len(hit) != n1:
        raise ValueError(f"D_c enters {len(hit)} states but has {n1} columns; the standard form "
                         "needs D1 square and invertible")
    if not all(np.count_nonzero(row) == 1 and row.max() == 1 for row in C_c):
        raise ValueError("C_c rows must be rows of the identity (each channel measures one state)")
    selected = [int(np.argmax(row)) for row in C_c]
    missing = [names[i] for i in hit if i not in selected]
    if missing:
        raise ValueError(f"states {missing} are hit by the disturbance but not measured; the "
                         "standard form needs y1 = x1")
    order = hit + [i for i in range(n) if i not in hit]
    y1 = [selected.index(i) for i in hit]
    T = np.eye(n)[order]
    S = np.eye(len(selected))[y1 + [j for j in range(len(selected)) if j not in y1]]
    C = S @ C_c @ T.T
    D = T @ D_c
    D1 = D[:n1]
    if abs(np.linalg.det(D1)) < 1e-12:
        raise ValueError("D1 is singular; the seed's method needs it invertible")
    return StandardForm(A_c=A_c, B_c=B_c, D_c=D_c, C_c=C_c, T=T, S=S, A=T @ A_c @ T.T,
                        B=T @ B_c, D=D, C=C, C1=C[:n1], C2=C[n1:], D1=D1, n1=n1,
                        state_names=names, measurement_names=channels)


def usv_standard_form(model: USVModel | None = None) -> StandardForm:
    """MODELS.md 1.3 for ``model`` (default: seed 000's USV): ``x = [r, p, v, psi, phi]``,
    ``y = [r, p, psi, phi]``, ``D1 = I2``. With ``wave_input="angle"`` (reading (b)) it is
    ``x = [psi, phi, v, r, p]``, ``y2 = [r, p]``, for which the LMI is infeasible."""
    model = USVModel() if model is None else model
    A_c, B_c, D_c = model.linearize()
    return standard_form(A_c, B_c, D_c, model.C, model.state_names, model.measured_names)


# -- 2. augmented descriptor system ------------------------------------------------------------
@dataclasses.dataclass(frozen=True, eq=False)
class AugmentedSystem:
    """MODELS.md 1.5's augmented system ``E_bar x_bar' = A_bar x_bar + ...`` and ``M``.

    ``x_bar = [x; eps]`` (``n_bar = n + m2``); ``MA = M A_bar``, ``MD = M D_bar = E1' D1``,
    ``R = [0; I]``, ``Cbar2 = [C2, I]``.
    """

    E: FloatArray
    Abar: FloatArray
    Dbar: FloatArray
    Nbar: FloatArray
    Cbar2: FloatArray
    R: FloatArray
    M: FloatArray
    MA: FloatArray
    MD: FloatArray
    n1: int


def augment(A: ArrayLike, D: ArrayLike, C2: ArrayLike) -> AugmentedSystem:
    """The augmented descriptor system of a plant in standard form.

    :param A: ``(n, n)`` standard-form state matrix, 1/s.
    :param D: ``(n, n1)`` disturbance matrix ``[D1; 0]``.
    :param C2: ``(m2, n)`` rows of the quantized outputs ``y2`` (full width).
    :raises ValueError: shapes, or ``D``/``C2`` not in standard form.
    """
    A, D, C2 = (np.atleast_2d(np.asarray(a, dtype=float)) for a in (A, D, C2))
    n, n1, m2 = A.shape[0], D.shape[1], C2.shape[0]
    if A.shape != (n, n) or D.shape[0] != n or C2.shape[1] != n:
        raise ValueError(f"shapes A {A.shape}, D {D.shape}, C2 {C2.shape} do not fit together")
    if np.any(D[n1:]) or abs(np.linalg.det(D[:n1])) < 1e-12:
        raise ValueError("D must be [D1; 0] with D1 invertible (standard form)")
    if np.any(C2[:, :n1]):
        raise ValueError("C2 must not measure x1 (standard form: y1 = x1, y2 = C2 x2)")
    eye, zero = np.eye(m2), np.zeros
    E = np.block([[np.eye(n), zero((n, m2))], [zero((m2, n)), zero((m2, m2))]])
    Abar = np.block([[A, zero((n, m2))], [zero((m2, n)), -eye]])
    R = np.vstack([zero((n, m2)), eye])
    Cbar2 = np.hstack([C2, eye])
    M = np.linalg.inv(E + R @ Cbar2)
    Dbar = np.vstack([D, zero((m2, n1))])
    return AugmentedSystem(E=E, Abar=Abar, Dbar=Dbar, Nbar=R.copy(), Cbar2=Cbar2, R=R, M=M,
                           MA=M @ Abar, MD=M @ Dbar, n1=n1)


# -- 3. LMI design -----------------------------------------------------------------------------
class SolverWarning(UserWarning):
    """A warning from an LMI solver, or a disagreement between solvers."""


class LMIInfeasibleError(ValueError):
    """The PD observer's LMI has no solution; :attr:`condition` names the condition that fails.

    :param condition: ``"detectability"`` (``(M A_bar, C_bar2)`` not detectable),
        ``"decay_rate"`` (``alpha`` too large; :attr:`alpha_max` the largest feasible one found),
        ``"matching"`` (feasible only without the block-diagonal ``P``), ``"decoupling"`` (the
        ``"decoupled"`` objective's extra constraints) or ``"numerical"``.
    """

    def __init__(self, message: str, condition: str, alpha_max: float | None,
                 solver_status: dict[str, str]) -> None:
        super().__init__(message)
        self.condition, self.alpha_max, self.solver_status = condition, alpha_max, solver_status


@dataclasses.dataclass(frozen=True, eq=False)
class PDObserverDesign:
    """A solved PD-observer LMI, re-verified with eigenvalues after the solve.

    ``min_eig_P > 0`` and ``max_eig_lmi < 0`` are the checked certificate;
    ``quantization_gain`` is the H-infinity norm (frequency grid) from ``eps`` to the error of the
    ``protect``-ed states (standard-form indices); 0 for ``objective="decoupled"``.
    """

    Ls: FloatArray
    P: FloatArray
    P1: FloatArray
    As: FloatArray
    N: FloatArray
    M: FloatArray
    R: FloatArray
    alpha: float
    eigenvalues_As: NDArray[np.complex128]
    min_eig_P: float
    max_eig_lmi: float
    solver_status: dict[str, str]
    solver_feasible: dict[str, bool]
    solver_used: str
    solvers_agree: bool
    feasible: bool
    objective: str
    protect: tuple[int, ...]
    quantization_gain: float
    augmented: AugmentedSystem
    warnings: list[str]


def design_pd_observer(A: ArrayLike, D: ArrayLike, C2: ArrayLike, alpha: float = 0.05, *,
                       objective: Objective = "feasibility",
                       protect: Sequence[int] | None = None,
                       solvers: Sequence[str] = DEFAULT_SOLVERS,
                       margin: float = 1e-3) -> PDObserverDesign:
    """Solve the PD observer's LMI with every solver in ``solvers`` and check they agree.

    ``objective="feasibility"`` is the seed's LMI (normalised ``P >= I``, strict by
    ``margin * I``). ``"decoupled"`` adds ``Y[protect] = 0`` and ``P[protect, others] = 0``, so
    ``Ls[protect] = 0``: the protected states' error then obeys ``e' = (M A_bar)[protect] e``,
    untouched by ``eps`` and ``d`` provided those states are autonomous in ``M A_bar`` (checked).

    :param A: ``(n, n)`` standard-form state matrix, 1/s.
    :param D: ``(n, n1)`` disturbance matrix ``[D1; 0]``.
    :param C2: ``(m2, n)`` rows of ``y2``.
    :param alpha: guaranteed decay rate of ``V = e' P e``, 1/s (``V' <= -2 alpha V + ...``).
    :param objective: ``"feasibility"`` (the seed's) or ``"decoupled"``.
    :param protect: standard-form indices of the states whose error ``eps`` must not reach
        (default: those no output measures, the USV's sway speed).
    :param solvers: cvxpy solver names; the first verified solution is used, all must agree.
    :param margin: strictness margin of the LMIs (``P >= I`` normalisation).
    :raises LMIInfeasibleError: no verified solution; the message names the failing condition.
    """
    aug = augment(A, D, C2)
    alpha = float(alpha)
    if not (math.isfinite(alpha) and alpha >= 0):
        raise ValueError(f"alpha={alpha!r} is invalid: must be finite and >= 0")
    if objective not in ("feasibility", "decoupled"):
        raise ValueError(f"objective={objective!r} is invalid: 'feasibility' or 'decoupled'")
    if not solvers:
        raise ValueError("solvers is empty")
    protect = tuple(_unmeasured(aug) if protect is None else (int(i) for i in protect))
    check_positive("margin", margin)
    if objective == "decoupled":
        _check_decouplable(aug, protect)

    results = {s: _solve(aug, alpha, True, objective, protect, margin, s) for s in solvers}
    status = {s: r.status for s, r in results.items()}
    verified = {s: r.verified for s, r in results.items()}
    messages = [f"{s}: {m}" for s, r in results.items() for m in r.messages]
    agree = len(set(verified.values())) == 1
    if not agree:
        messages.append("solvers disagree on feasibility: " + ", ".join(
            f"{s} {'feasible' if verified[s] else 'infeasible'} ({status[s]})" for s in solvers))
    for message in messages:
        warnings.warn(message, SolverWarning, stacklevel=2)
    if not any(verified.values()):
        condition, alpha_max, why = _diagnose(aug, alpha, objective, protect, margin,
                                              solvers[0])
        raise LMIInfeasibleError(f"PD observer LMI infeasible (alpha={alpha:g}, objective="
                                 f"{objective}; solver status {status}): {why}",
                                 condition, alpha_max, status)
    used = next(s for s in solvers if verified[s])
    P, Y = results[used].P, results[used].Y
    Ls = np.linalg.solve(P, Y)
    As = aug.MA - Ls @ aug.Cbar2
    return PDObserverDesign(
        Ls=Ls, P=P, P1=P[:aug.n1, :aug.n1], As=As, N=aug.MA @ aug.R, M=aug.M, R=aug.R,
        alpha=alpha, eigenvalues_As=np.linalg.eigvals(As),
        min_eig_P=float(np.linalg.eigvalsh(P).min()),
        max_eig_lmi=_max_eig_lmi(aug, P, Y, alpha), solver_status=status,
        solver_feasible=verified, solver_used=used, solvers_agree=agree, feasible=True,
        objective=objective, protect=protect,
        quantization_gain=quantization_gain(As, aug.R, protect), augmented=aug,
        warnings=messages)


def largest_decay_rate(A: ArrayLike, D: ArrayLike, C2: ArrayLike, *, upper: float = 1.0,
                       tol: float = 1e-4, solver: str = DEFAULT_SOLVERS[0],
                       margin: float = 1e-3) -> float | None:
    """Largest ``alpha`` in ``[0, upper]`` for which the seed's LMI is feasible (bisection to
    ``tol``, 1/s), or None if it is infeasible even at ``alpha = 0``."""
    aug = augment(A, D, C2)
    return _bisect_alpha(aug, 0.0, upper, margin, solver, tol)


def quantization_gain(As: ArrayLike, R: ArrayLike, protect: Sequence[int]) -> float:
    """H-infinity norm of ``eps -> e[protect]`` for ``e' = As e + R eps`` (log frequency grid
    1e-4..1e4 rad/s plus 0; a lower bound within the grid's resolution)."""
    As, R = np.asarray(As, dtype=float), np.asarray(R, dtype=float)
    if not protect:
        return 0.0
    w = np.concatenate([[0.0], np.logspace(-4, 4, 801)])
    resolvent = np.linalg.solve(1j * w[:, None, None] * np.eye(As.shape[0]) - As, R)
    return float(np.linalg.norm(resolvent[:, list(protect), :], ord=2, axis=(1, 2)).max())


@dataclasses.dataclass
class _Solution:
    status: str
    verified: bool
    P: FloatArray | None
    Y: FloatArray | None
    messages: list[str]


def _unmeasured(aug: AugmentedSystem) -> list[int]:
    """States that no output row touches (x1 is measured by y1)."""
    n = aug.MA.shape[0] - aug.R.shape[1]
    seen = np.abs(aug.Cbar2[:, :n]).sum(axis=0) > 0
    return [j for j in range(aug.n1, n) if not seen[j]]


def _check_decouplable(aug: AugmentedSystem, protect: Sequence[int]) -> None:
    """The protected states must be valid, unmeasured and driven by no other state."""
    n = aug.MA.shape[0] - aug.R.shape[1]
    if not protect or not all(aug.n1 <= i < n for i in protect):
        raise ValueError(f"protect={list(protect)} is invalid: needs indices of x2 states "
                         f"({aug.n1}..{n - 1}, standard-form order)")
    others = [j for j in range(aug.MA.shape[0]) if j not in protect]
    if np.any(aug.MA[np.ix_(protect, others)]) or np.any(aug.Cbar2[:, list(protect)]):
        raise ValueError(f"states {list(protect)} cannot be decoupled from the quantization "
                         "error: other states drive them, or y2 measures them")


def _solve(aug: AugmentedSystem, alpha: float, matched: bool, objective: str,
           protect: Sequence[int], margin: float, solver: str) -> _Solution:
    """Build and solve one LMI with one solver; capture its warnings and verify the result."""
    try:  # an optional, heavy dependency: imported only when designing
        import cvxpy as cp
    except ImportError as error:
        raise ImportError("the PD observer's LMI design needs cvxpy: "
                          'pip install "marine-envs[estimators]"') from error

    nb, n1, m2 = aug.MA.shape[0], aug.n1, aug.R.shape[1]
    if matched:
        P1 = cp.Variable((n1, n1), symmetric=True)
        P2 = cp.Variable((nb - n1, nb - n1), symmetric=True)
        P = cp.bmat([[P1, np.zeros((n1, nb - n1))], [np.zeros((nb - n1, n1)), P2]])
    else:
        P = cp.Variable((nb, nb), symmetric=True)
    Y = cp.Variable((nb, m2))
    body = P @ aug.MA - Y @ aug.Cbar2
    lmi = body + body.T + 2 * alpha * P
    constraints = [P >> np.eye(nb), (lmi + lmi.T) / 2 << -margin * np.eye(nb)]
    if objective == "decoupled":  # Ls[protect] = P^-1 Y [protect] = 0
        keep = np.eye(nb)[list(protect)]
        rest = np.eye(nb)[[j for j in range(nb) if j not in protect]]
        constraints += [keep @ Y == 0, keep @ P @ rest.T == 0]
    problem = cp.Problem(cp.Minimize(0), constraints)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            problem.solve(solver=solver)
            status = str(problem.status)
        except (cp.error.SolverError, ValueError) as error:  # not installed, or it failed
            status = f"solver_error: {error}"
    messages = [str(w.message) for w in caught]
    if status == "optimal_inaccurate":
        messages.append("solution flagged inaccurate by the solver")
    if not status.startswith("optimal") or P.value is None or Y.value is None:
        return _Solution(status, False, None, None, messages)
    P_val, Y_val = np.asarray(P.value), np.asarray(Y.value)
    P_val = (P_val + P_val.T) / 2
    min_eig, max_lmi = np.linalg.eigvalsh(P_val).min(), _max_eig_lmi(aug, P_val, Y_val, alpha)
    verified = bool(min_eig > 0 and max_lmi < 0)
    if not verified:
        messages.append(f"status {status} but the certificate fails the eigenvalue check "
                        f"(min eig P {min_eig:.3g}, max eig LMI {max_lmi:.3g})")
    return _Solution(status, verified, P_val, Y_val, messages)


def _max_eig_lmi(aug: AugmentedSystem, P: FloatArray, Y: FloatArray, alpha: float) -> float:
    """Largest eigenvalue of ``He(P M A_bar - Y C_bar2) + 2 alpha P`` (must be < 0)."""
    body = P @ aug.MA - Y @ aug.Cbar2
    return float(np.linalg.eigvalsh(body + body.T + 2 * alpha * P).max())


def _feasible(aug: AugmentedSystem, alpha: float, matched: bool, margin: float,
              solver: str) -> bool:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # probing relaxations: only the verdict matters here
        return _solve(aug, alpha, matched, "feasibility", (), margin, solver).verified


def _bisect_alpha(aug: AugmentedSystem, low: float, high: float, margin: float, solver: str,
                  tol: float = 1e-4) -> float | None:
    """Largest feasible alpha in ``[low, high]`` of the matched LMI (None: not even ``low``)."""
    if not _feasible(aug, low, True, margin, solver):
        return None
    if _feasible(aug, high, True, margin, solver):
        return high
    while high - low > tol:
        mid = (low + high) / 2
        low, high = (mid, high) if _feasible(aug, mid, True, margin, solver) else (low, mid)
    return low


def _unobservable_modes(MA: FloatArray, C: FloatArray) -> list[complex]:
    """Eigenvalues of ``MA`` that ``C`` cannot see (PBH rank test)."""
    scale = max(1.0, np.abs(MA).max())
    modes = []
    for lam in np.linalg.eigvals(MA):
        pencil = np.vstack([lam * np.eye(MA.shape[0]) - MA, C])
        if np.linalg.svd(pencil, compute_uv=False)[-1] < 1e-8 * scale:
            modes.append(complex(lam))
    return modes


def _listed(modes: Sequence[complex]) -> str:
    return ", ".join(f"{m.real:.4g}{m.imag:+.4g}j" for m in modes) or "none"


def _diagnose(aug: AugmentedSystem, alpha: float, objective: str, protect: Sequence[int],
              margin: float, solver: str) -> tuple[str, float | None, str]:
    """Which condition makes the LMI infeasible: re-solve relaxations to find out."""
    modes = _unobservable_modes(aug.MA, aug.Cbar2)
    slowest = max((m.real for m in modes), default=-math.inf)
    listed = _listed(modes)
    # with a block-diagonal P the x2 block must satisfy a Lyapunov inequality of its own
    x2 = list(range(aug.n1, aug.MA.shape[0]))
    hidden = _listed(_unobservable_modes(aug.MA[np.ix_(x2, x2)], aug.Cbar2[:, x2]))
    if slowest >= 0:
        return "detectability", None, (
            f"(M A_bar, C_bar2) is not detectable: mode(s) {listed} cannot be seen from q(y2) "
            "and do not decay, so no gain Ls can stabilise the error")
    if slowest >= -alpha:
        return "decay_rate", -slowest, (
            f"the decay rate alpha={alpha:g} is too large even without the matching condition: "
            f"unobservable mode(s) {listed} decay at {-slowest:.4g} only, so alpha < "
            f"{-slowest:.4g}")
    if not _feasible(aug, alpha, False, margin, solver):
        return "numerical", None, (
            "the LMI without the matching condition should be feasible (the pair is detectable at "
            "this alpha) but the solver failed; check scaling or try another solver")
    if objective == "decoupled" and _feasible(aug, alpha, True, margin, solver):
        own = -max(np.linalg.eigvals(aug.MA[np.ix_(protect, protect)]).real)
        return "decoupling", own, (
            f"the seed's LMI is feasible but not with the protected states {list(protect)} "
            f"decoupled: their own modes decay at {own:.4g} only, so alpha < {own:.4g}")
    alpha_max = _bisect_alpha(aug, 0.0, alpha, margin, solver)
    if alpha_max is None:
        return "matching", None, (
            "the matching condition (block-diagonal P, P M D_bar = E1' P1 D1) makes it "
            f"infeasible: without it the LMI is feasible at alpha={alpha:g}, with it not even at "
            f"alpha=0: the x2 block must then be stabilisable on its own, and its mode(s) "
            f"{hidden} are invisible to y2 inside that block")
    return "decay_rate", alpha_max, (
        f"the decay rate alpha={alpha:g} is too large under the matching condition "
        f"(block-diagonal P, P M D_bar = E1' P1 D1): the largest feasible alpha with it is "
        f"about {alpha_max:.4g}, set by the x2-block mode(s) {hidden} that y2 cannot see inside "
        f"that block (without the matching condition alpha={alpha:g} would be feasible)")


# -- 4. the observer ---------------------------------------------------------------------------
class QuantizedPDObserver(HeldInputObserver):
    """A batch of seed 000's PD observers, with the network scheme of MODELS.md 1.4 built in.

    Give :meth:`update` the raw sensor output ``y`` (the original channels, e.g. the USV's
    ``[r, psi, p, phi]``). At the sensor side the observer forms ``e1 = x_hat1 - y1``, quantizes it
    with the zooming quantizer 1 (relative law, ``mu1 = 2 k ||e1|| / sqrt(m1)``) and ``y2`` with the
    static quantizer 2 (step ``mu2``), and computes ``us1`` from ``q(e1)``. Observer 1 (sensor)
    and observer 2 (controller) receive the same ``q(e1)``, ``mu1``, ``q(y2)``, start from the same
    state and integrate the same equations, so their states coincide: one copy serves both (the
    sensor side reads ``x_hat1`` from it). The received data are held until the next sample and
    :meth:`predict` integrates ``xi' = As xi + M B_bar u + N q(y2) + M D_bar us1`` exactly.

    ``x`` is ``x_hat`` in the ORIGINAL state order; ``P`` is NaN (no covariance). The transmitted
    signals are :attr:`q_e1`, :attr:`mu1` and :attr:`q_y2`; :attr:`us1` and :attr:`xi` are exposed
    too. A masked or NaN channel holds its last valid value at the sensor (so a missing ``y1``
    component keeps its old value in ``e1``, a missing ``y2`` component its old ``q(y2)``).

    :param form: the plant in standard form (:func:`standard_form`).
    :param design: the solved LMI (:func:`design_pd_observer`) for ``form.A, form.D, form.C2``.
    :param mu2: step of quantizer 2, in the units of ``y2`` (rad for the USV); a scalar, or one
        step per observer ``(N,)`` (then the batch size is ``N``).
    :param k: zoom rate of quantizer 1, in (0, 1).
    :param rho: amplitude of ``us1``, in the disturbance's unit (rad/s^2); must bound ``||d||``.
    :param delta: smoothing constant of ``us1`` (> 0), in the units of ``P1 e1``.
    :param dt: nominal step of :meth:`predict`, s.
    """

    def __init__(self, form: StandardForm, design: PDObserverDesign, *,
                 mu2: float | ArrayLike = 0.5,
                 k: float = 0.6, rho: float = 0.6, delta: float = 0.01,
                 dt: float = 1e-3) -> None:
        if not (isinstance(k, int | float) and 0 < k < 1):
            raise ValueError(f"k={k!r} is invalid: the zoom rate must be in (0, 1)")
        if not (isinstance(rho, int | float) and math.isfinite(rho) and rho >= 0):
            raise ValueError(f"rho={rho!r} is invalid: must be finite and >= 0")
        aug = design.augmented
        if aug.MA.shape[0] != form.A.shape[0] + form.C2.shape[0] or aug.n1 != form.n1 or \
                not np.allclose(aug.MA[:form.A.shape[0], :form.A.shape[0]], form.A):
            raise ValueError("design does not belong to form (design it for form.A, D, C2)")
        self.form, self.design = form, design
        self.mu2, self.k = check_steps("mu2", mu2), float(k)
        self.rho, self.delta = float(rho), check_positive("delta", delta)
        self._n, self._T_inv = form.A.shape[0], np.linalg.inv(form.T)
        self._P1D1 = design.P1 @ form.D1  # row form of D1' P1 q(e1)
        MB = aug.M @ np.vstack([form.B, np.zeros((form.C2.shape[0], form.B.shape[1]))])
        super().__init__(design.As, MB, np.hstack([design.N, aug.MD]), form.C_c, dt,
                         form.state_names, form.measurement_names, np.size(mu2))

    @classmethod
    def for_usv(cls, model: USVModel | None = None, *, alpha: float = 0.05,
                objective: Objective = "feasibility", mu2: float | ArrayLike = 0.5,
                k: float = 0.6,
                rho: float = 0.6, delta: float = 0.01, dt: float = 1e-3,
                solvers: Sequence[str] = DEFAULT_SOLVERS) -> QuantizedPDObserver:
        """Seed 000's observer for ``model`` (default: the seed's USV), designed here.

        :param alpha: decay rate of the LMI, 1/s.
        :param objective: ``"feasibility"`` (the seed's LMI) or ``"decoupled"``.
        :param mu2: step of quantizer 2, rad. Other parameters as in the class.
        """
        form = usv_standard_form(model)
        design = design_pd_observer(form.A, form.D, form.C2, alpha, objective=objective,
                                    solvers=solvers)
        return cls(form, design, mu2=mu2, k=k, rho=rho, delta=delta, dt=dt)

    def bind(self, batch_size: int) -> None:
        self._mu2 = steps_per_row("mu2", self.mu2, batch_size)
        n1 = self.form.n1
        self.quantizer1 = ZoomingQuantizer([range(n1)], k=self.k, law="relative")
        self.quantizer1.bind(int(batch_size))
        self.q_e1 = np.zeros((batch_size, n1))
        self.mu1 = np.zeros(batch_size)
        super().bind(batch_size)

    @property
    def q_y2(self) -> FloatArray:
        """``q(y2)`` last received ``(N, m2)``, standard-form order."""
        return self.held[:, :self.form.C2.shape[0]]

    @property
    def us1(self) -> FloatArray:
        """Disturbance-rejecting input ``(N, n1)`` in use, disturbance units."""
        return self.held[:, self.form.C2.shape[0]:]

    @property
    def xi(self) -> FloatArray:
        """Intermediate variable ``xi`` ``(N, n + m2)``."""
        return self.z

    @property
    def eps_hat(self) -> FloatArray:
        """Estimate of the quantization error ``eps = q(y2) - y2``: ``xi_eps + q(y2)``."""
        return self.z[:, self._n:] + self.q_y2

    def _restart(self, rows: NDArray[np.intp], x0: FloatArray) -> None:
        x_std = x0 @ self.form.T.T
        y2 = x_std @ self.form.C2.T  # q(y2) before the first sample: the predicted y2
        self.z[rows] = np.hstack([x_std, -y2])  # eps_hat = 0
        self.held[rows] = np.hstack([y2, np.zeros((rows.size, self.form.n1))])
        self.q_e1[rows], self.mu1[rows] = 0.0, 0.0

    def _receive(self, y: FloatArray) -> FloatArray:
        n1 = self.form.n1
        y_std = y @ self.form.S.T
        e1 = self.z[:, :n1] - y_std[:, :n1]
        self.q_e1 = self.quantizer1(e1)
        self.mu1 = self.quantizer1.mu[:, 0].copy()
        q_y2 = quantize(y_std[:, n1:], self._mu2)
        push = self.q_e1 @ self._P1D1
        us1 = -self.rho * push / (np.linalg.norm(push, axis=1, keepdims=True) + self.delta)
        return np.hstack([q_y2, us1])

    def _estimate(self, z: FloatArray) -> FloatArray:
        return z[:, :self._n] @ self._T_inv.T
