"""The USV observer patent's proportional-derivative (PD) observer on quantized network data
(docs/models.md 1.3-1.6).

The method, in the patent's symbols (docs/models.md 1.5 gives the reconstruction):

1. **Standard form.** ``x = T x_c``, ``y = S y_c`` put the disturbance-hit, directly measured
   states first: ``x = [x1; x2]``, ``D = [D1; 0]`` with ``D1`` invertible, ``y1 = x1``,
   ``y2 = C2 x`` (:func:`standard_form`, :func:`usv_standard_form`).
2. **Network.** The sensor sends ``q(e1)`` (``e1 = x_hat1 - y1``, zooming quantizer with
   ``mu1 = 2 k ||e1|| / sqrt(m1)``, ``mu1`` sent along) and ``q(y2)`` (static step ``mu2``).
3. **Augmented descriptor system** ``x_bar = [x; eps]``, ``eps = q(y2) - y2``, and the matrix
   ``M = (E_bar + R C_bar2)^-1`` (:func:`augment`).
4. **PD observer** ``xi' = As xi + M B_bar u + N q(y2) + M D_bar us1``,
   ``x_bar_hat = xi + R q(y2)``, ``As = M A_bar - Ls C_bar2``, ``N = As R + Ls``, with the
   disturbance-rejecting input ``us1 = -rho D1' P1 q(e1) / (||D1' P1 q(e1)|| + delta)`` (the patent
   writes ``P1 q(e1)``; ``D1 = I`` for the USV).
5. **LMI** (:func:`design_pd_observer`): ``P = blkdiag(P1, P2) > 0``, ``Y`` with
   ``He(P M A_bar - Y C_bar2) + 2 alpha P < 0``; ``Ls = P^-1 Y``. The block-diagonal ``P`` is the
   matching condition ``P M D_bar = E1' P1 D1`` that turns the disturbance term into
   ``-2 e1' P1 D1 (d - us1) <= 2 rho delta``.

Findings the code documents (numbers in the reproduction ``usv-quantized-observer``):

* The error obeys ``e_bar' = As e_bar + E1'(d - us1) + R eps``: the quantization error ``eps``
  does not cancel, so the patent's feasibility-only design leaves an error that grows with ``mu2``.
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

from .descriptor import AugmentedSystem, StandardForm, augment, standard_form, usv_standard_form
from .lmi import (
    DEFAULT_SOLVERS,
    LMIInfeasibleError,
    Objective,
    PDObserverDesign,
    SolverWarning,
    design_pd_observer,
    largest_decay_rate,
    quantization_gain,
)
from .observer import QuantizedPDObserver

__all__ = [
    "DEFAULT_SOLVERS",
    "AugmentedSystem",
    "LMIInfeasibleError",
    "Objective",
    "PDObserverDesign",
    "QuantizedPDObserver",
    "SolverWarning",
    "StandardForm",
    "augment",
    "design_pd_observer",
    "largest_decay_rate",
    "quantization_gain",
    "standard_form",
    "usv_standard_form",
]
