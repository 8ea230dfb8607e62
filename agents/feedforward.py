"""Model-based thrust feed-forward plus LQR feedback for the ROV of the morphing-robot patent.

The patent ends with "the identified coefficients feed thrust feed-forward for motion control": from
the reference motion and the hydrodynamic coefficients, predict the drag and moments the robot
will meet and command the thrust that cancels them, so that the feedback only corrects what the
model does not predict. Here::

    tau = tau_ff - K (x_hat - x_ref) [- K_i z]
    tau_ff = M(s) nu_ref_dot - (-C_RB(nu_ref) nu_ref + tau_hyd(nu_ref; theta) + tau_s(eta_ref))

``tau_ff`` is the generalised force that makes the model with coefficients ``theta`` follow the
reference exactly (inverse dynamics); ``M(s)``, ``C_RB`` and the restoring forces use the known
shape ``s`` (the robot commands its own morph), only the viscous coefficients ``theta`` differ
between an identified and a nominal feed-forward. ``K`` is the discrete LQR of the model
linearised at cruise (1.5 m/s, cruise shape), on the velocities, depth and attitude; the roll
moment is not commanded (the thrusters have no roll authority, docs/models.md 3.5).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from agents.lqr import lqr, lqr_integral
from marine_envs.models.rov import SEED_COEFFICIENTS, ROVModel

FloatArray = NDArray[np.float64]
DEG = math.pi / 180
#: States the feedback acts on (the ROV's state names); x, y and the shape s are not fed back.
FEEDBACK_STATES = ("u", "v", "w", "p", "q", "r", "z", "phi", "theta", "psi")
#: Bryson's rule: acceptable error per state (m/s, rad/s, m, rad); roll is left to the BG
#: pendulum (no roll authority), so phi and p carry no weight.
ERROR_SCALES = {"u": 0.05, "v": 0.05, "w": 0.05, "q": 5 * DEG, "r": 5 * DEG, "z": 0.1,
                "theta": 3 * DEG, "psi": 3 * DEG}
#: Commanded inputs: every force but the roll moment K.
COMMANDED = ("X", "Y", "Z", "M", "N")


class FeedforwardTracker:
    """LQR tracking of a reference motion with a model-based thrust feed-forward.

    :param model: the ROV model (its M(s), C_RB and restoring forces are used as known).
    :param dt: control period, s.
    :param coefficients: names of the viscous coefficients the feed-forward takes as input.
    :param error_scales: ``{state: acceptable error}`` (Bryson weights of the LQR), state units.
    :param integral: ``{state: weight}`` of integral action (e.g. ``{"u": 1.0}``), or None.
    """

    def __init__(self, model: ROVModel, dt: float,
                 coefficients: Sequence[str] = SEED_COEFFICIENTS,
                 error_scales: Mapping[str, float] | None = None,
                 integral: Mapping[str, float] | None = None) -> None:
        self.model, self.dt, self.coefficients = model, float(dt), tuple(coefficients)
        names = model.state_names
        self._states = np.array([names.index(n) for n in FEEDBACK_STATES])
        self._inputs = np.array([model.input_names.index(n) for n in COMMANDED])
        scales = ERROR_SCALES if error_scales is None else error_scales
        self.K, self.K_i, self._integrated = self._design(scales, integral or {})
        self.low, self.high = model.u_bounds
        self.low[3] = self.high[3] = 0.0  # no roll moment
        # c(s) and M(s) are affine in the shape s
        c0, c1 = model.coefficients(0.0), model.coefficients(1.0)
        self._c0 = np.array([c0[n] for n in self.coefficients])
        self._dc = np.array([c1[n] for n in self.coefficients]) - self._c0
        self._M0, self._dM = model.mass_matrix(0.0), model.mass_matrix(1.0) - model.mass_matrix(0.0)
        self.z: FloatArray | None = None

    def _design(self, scales: Mapping[str, float], integral: Mapping[str, float]):
        """Discrete LQR gains ``(K (6, 13), K_i (6, n_z), integrated indices)``."""
        m = self.model
        A, B, _ = m.linearize(m.x0, m.u0)
        idx, inputs = self._states, self._inputs
        A, B = A[np.ix_(idx, idx)], B[np.ix_(idx, inputs)]
        Q = np.diag([1 / scales[n] ** 2 if n in scales else 0.0 for n in FEEDBACK_STATES])
        low, high = m.u_bounds
        R = np.diag(1 / np.maximum(-low, high)[inputs] ** 2)
        K = np.zeros((6, len(m.state_names)))
        K_i = np.zeros((6, len(integral)))
        integrated = [FEEDBACK_STATES.index(n) for n in integral]
        if integrated:
            gain = lqr_integral(A, B, Q, R, integrated, list(integral.values()), dt=self.dt).K
            K_i[inputs] = gain[:, idx.size:]
        else:
            gain = lqr(A, B, Q, R, dt=self.dt).K
        K[np.ix_(inputs, idx)] = gain[:, :idx.size]
        return K, K_i, idx[integrated] if integrated else np.zeros(0, dtype=int)

    def feedforward(self, x_ref: ArrayLike, nu_dot_ref: ArrayLike,
                    theta: ArrayLike) -> FloatArray:
        """Inverse dynamics of the reference with coefficients ``theta`` (N, N m).

        :param x_ref: reference states ``(N, 13)`` (velocities, attitude; ``s`` = the current
            shape, known).
        :param nu_dot_ref: reference body accelerations ``(N, 6)``, m/s^2 and rad/s^2.
        :param theta: the coefficients ``(N, p)`` at the current shape (the identified values,
            or the cruise values for a nominal feed-forward), their units.
        :return: ``(N, 6)`` generalised forces; the roll moment is the model's, not commanded.
        """
        m = self.model
        x_ref = np.asarray(x_ref, dtype=float)
        theta = np.asarray(theta, dtype=float)
        s = x_ref[:, 12]
        d = np.zeros((x_ref.shape[0], 4))
        d[:, 3] = s  # hold the shape: no morph rate in the feed-forward
        # forces at c(s) plus the regressors times the difference to theta
        phi = m.hydrodynamic_regressors(x_ref, self.coefficients, d)
        forces = m.forces(x_ref, np.zeros(6), d) + np.einsum(
            "nij,nj->ni", phi, theta - (self._c0 + s[:, None] * self._dc))
        nu_dot_ref = np.asarray(nu_dot_ref, dtype=float)
        inertia = nu_dot_ref @ self._M0.T + s[:, None] * (nu_dot_ref @ self._dM.T)
        return inertia - forces

    def __call__(self, x_hat: ArrayLike, x_ref: ArrayLike, nu_dot_ref: ArrayLike,
                 theta: ArrayLike) -> FloatArray:
        """Generalised forces ``(N, 6)`` (N, N m), within the thruster box, roll moment zero.

        :param x_hat: estimated states ``(N, 13)``.
        :param x_ref, nu_dot_ref, theta: as :meth:`feedforward`.
        """
        x_hat, x_ref = np.asarray(x_hat, dtype=float), np.asarray(x_ref, dtype=float)
        error = x_hat - x_ref
        error[:, 11] = (error[:, 11] + math.pi) % (2 * math.pi) - math.pi  # heading wraps
        tau = self.feedforward(x_ref, nu_dot_ref, theta) - error @ self.K.T
        if self._integrated.size:
            if self.z is None:
                self.z = np.zeros((x_hat.shape[0], self._integrated.size))
            tau -= self.z @ self.K_i.T
            # conditional integration (anti-windup): hold the integrals of a saturated row
            inside = (tau >= self.low) & (tau <= self.high)
            free = inside[:, self._inputs].all(axis=1)
            self.z[free] += self.dt * error[free][:, self._integrated]
        return np.clip(tau, self.low, self.high)

    def reset(self) -> None:
        """Zero the integral states."""
        self.z = None
