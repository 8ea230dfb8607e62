"""The PD observer's LMI design (docs/models.md 1.5): :func:`design_pd_observer`,
:func:`largest_decay_rate`, :func:`quantization_gain`. Needs cvxpy, imported only when solving."""

from __future__ import annotations

import dataclasses
import math
import warnings
from collections.abc import Sequence
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..base import FloatArray
from ..luenberger import check_positive
from .descriptor import AugmentedSystem, augment

Objective = Literal["feasibility", "decoupled"]

#: Solvers used by default; the first one's certificate is used, the others cross-check it.
DEFAULT_SOLVERS: tuple[str, ...] = ("CLARABEL", "SCS")


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

    ``objective="feasibility"`` is the patent's LMI (normalised ``P >= I``, strict by
    ``margin * I``). ``"decoupled"`` adds ``Y[protect] = 0`` and ``P[protect, others] = 0``, so
    ``Ls[protect] = 0``: the protected states' error then obeys ``e' = (M A_bar)[protect] e``,
    untouched by ``eps`` and ``d`` provided those states are autonomous in ``M A_bar`` (checked).

    :param A: ``(n, n)`` standard-form state matrix, 1/s.
    :param D: ``(n, n1)`` disturbance matrix ``[D1; 0]``.
    :param C2: ``(m2, n)`` rows of ``y2``.
    :param alpha: guaranteed decay rate of ``V = e' P e``, 1/s (``V' <= -2 alpha V + ...``).
    :param objective: ``"feasibility"`` (the patent's) or ``"decoupled"``.
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
    """Largest ``alpha`` in ``[0, upper]`` for which the patent's LMI is feasible (bisection to
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
            f"the patent's LMI is feasible but not with the protected states {list(protect)} "
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
