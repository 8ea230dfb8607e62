"""The quantized PD observer :class:`QuantizedPDObserver` with the network scheme of
docs/models.md 1.4 built in."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from marine_envs.models.usv import USVModel
from marine_envs.sensors import ZoomingQuantizer, quantize

from ..base import FloatArray
from ..luenberger import HeldInputObserver, check_positive, check_steps, steps_per_row
from .descriptor import StandardForm, usv_standard_form
from .lmi import DEFAULT_SOLVERS, Objective, PDObserverDesign, design_pd_observer


# -- 4. the observer ---------------------------------------------------------------------------
class QuantizedPDObserver(HeldInputObserver):
    """A batch of the USV observer patent's PD observers, with the network scheme of
    docs/models.md 1.4 built in.

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
        """The USV observer patent's observer for ``model`` (default: the patent's USV), designed
        here.

        :param alpha: decay rate of the LMI, 1/s.
        :param objective: ``"feasibility"`` (the patent's LMI) or ``"decoupled"``.
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
