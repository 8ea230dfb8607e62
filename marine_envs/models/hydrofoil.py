"""Hydrofoil: longitudinal heave/pitch of a small fully-submerged two-foil craft (the hydrofoil
AKF paper; docs/models.md section 2). Everything below is **[RECON]**: a first-principles
quasi-steady foil model built from the paper's table, with a few **[PROPOSED]** constants.

Geometry (earth frame x forward, z down, origin on the calm surface): ``xi`` is the depth of the
CG (positive down, so the trim ``xi0 = -1.04 m`` puts the CG above the water), ``theta`` is the
pitch (bow-up positive). Foil i sits at body ``(x_i, l)`` with ``x_1 = +l1`` (front) and
``x_2 = -l2`` (rear), at the bottom of the strut of length ``l``. For foil i = 1, 2::

    h_i     = xi + l*cos(theta) - x_i*sin(theta) + eta_i             submergence, m
    U_i     = U - u_w,i                                              inflow speed, m/s
    alpha_i = theta + alpha_s,i + (xi_dot - x_i*theta_dot + zeta_dot_i) / U_i       rad
    alpha_i = clip(alpha_i, -alpha_stall, +alpha_stall)                             stall
    C_L,i   = a_i * k(h_i/c_i) * alpha_i,   k(r) = (1 + 16 r^2) / (2 + 16 r^2)
    L_i     = 0.5*rho*U_i^2*S_i*C_L,i                                    N
    D_i     = 0.5*rho*U_i^2*S_i*(CD0 + C_L,i^2/(pi*AR_i))                N
    L_i = D_i = 0 when h_i <= 0 (foil broached)
    f       = 0.5*rho*U^2*CDs*cs*max(0, (h_1 + h_2)/2)                   strut drag, N

    m*xi_ddot    = m*g - (L_1 + L_2) - F0*sin(theta)
    J*theta_ddot = l1*L_1 - l2*L_2 + l3*F0 - l*(D_1 + D_2) - l4*f

with ``S_i = span_i*chord_i``, ``AR_i = span_i/chord_i`` and the lift slope ``a_i`` of Prandtl's
lifting line ``2 pi AR/(AR + 2)`` (default) or Helmbold's ``2 pi AR/(2 + sqrt(AR^2 + 4))``
(about 11 % lower). The thrust ``F0`` is held at its trim value, solved at construction from
``xi_ddot = theta_ddot = 0`` and ``F0 cos(theta0) = D_1 + D_2 + f`` at ``(xi0, theta0)``.

``x = [xi, theta, xi_dot, theta_dot]`` (m, rad, m/s, rad/s), absolute, not deviations from
trim; ``u = [alpha_s1, alpha_s2]`` (rad), the absolute foil rotation angles;
``d = [zeta_dot_1, zeta_dot_2, eta_1, eta_2, u_w1, u_w2]`` (m/s, m/s, m, m, m/s, m/s): the upward
sub-surface orbital velocity at each foil, the surface elevation above each foil (positive up)
and the horizontal orbital velocity along +x at each foil (docs/models.md 2.3-2.4). The hydrofoil
AKF paper's model uses only the ``zeta_dot`` channels; ``eta`` and ``u_w`` belong to the richer
truth model.

Options: ``added_mass=True`` adds the heave added mass of each foil,
``rho*pi*(c/2)^2*b*AR/(1 + AR)`` **[PROPOSED formula]** (19.7 kg front, 4.0 kg rear), acting at
the foil on its vertical acceleration ``xi_ddot - x_i*theta_ddot``; this couples the heave and
pitch inertia through a constant 2x2 mass matrix (wave-induced added-mass forces are not
modelled). Left out, as docs/models.md 2.6 lists: the lift-below-CG pendulum term, unsteady lift
lag, ventilation. Linearised at trim the model has one slow unstable real pole (+0.17 1/s, heave)
and a stiff pitch/heave pair; with the paper's LQR a closed-loop pole sits near -8846 1/s, so
integrate with dt <= 1e-4 s (RK4) or discretise the linearisation exactly.
"""

from __future__ import annotations

import dataclasses
import math
from typing import ClassVar, Literal

import numpy as np

from ..compiled import Equations, jit
from .base import FloatArray, VehicleModel, require


@dataclasses.dataclass(frozen=True)
class HydrofoilParams:
    """Parameters of the hydrofoil model; names are docs/models.md's symbols. SI units, radians."""

    m: float = 102.04  #: mass, kg  [SEED]
    J: float = 14.35  #: pitch moment of inertia J_yy, kg m^2  [SEED]
    g: float = 9.80  #: gravity, m/s^2  [SEED: the hydrofoil AKF paper uses 9.80]
    rho: float = 1025.0  #: seawater density, kg/m^3  [global convention]
    #: strut ("connecting rod") length: the foils sit l below the CG, m  [SEED; RECON reading]
    l: float = 2.0  # noqa: E741 (docs/models.md symbol)
    l1: float = 0.2  #: front foil ahead of the CG, m  [SEED]
    l2: float = 1.0  #: rear foil behind the CG, m  [SEED]
    l3: float = 1.9  #: thrust line below the CG, m  [SEED]
    l4: float = 0.2  #: strut-drag moment arm, m  [SEED; taken literally from the paper]
    span1: float = 0.67  #: front foil span, m  [SEED]
    chord1: float = 0.22  #: front foil chord, m  [SEED]
    span2: float = 0.39  #: rear foil span, m  [SEED]
    chord2: float = 0.13  #: rear foil chord, m  [SEED]
    U: float = 6.08  #: forward speed, held constant, m/s  [SEED]
    theta0: float = math.radians(2.0)  #: trim pitch, rad  [SEED]
    xi0: float = -1.04  #: trim CG depth (positive down; negative = above water), m  [SEED]
    CD0: float = 0.008  #: foil profile drag coefficient, -  [PROPOSED]
    CDs: float = 0.012  #: strut drag coefficient, -  [PROPOSED]
    cs: float = 0.10  #: strut chord, m  [PROPOSED]
    alpha_stall: float = math.radians(12.0)  #: stall clip on the angle of attack, rad [PROPOSED]
    lift_slope: Literal["prandtl", "helmbold"] = "prandtl"  #: lift-slope formula  [RECON choice]
    added_mass: bool = False  #: add the foils' heave added mass  [PROPOSED; off as in the paper]
    #: foil rotation limit |alpha_s,i| <= alpha_max, rad  [PROPOSED: 15 deg, a little beyond the
    #: 12 deg stall so the controller can reach stall but not flip the foil]
    alpha_max: float = math.radians(15.0)

    def __post_init__(self) -> None:
        positive = ("m", "J", "g", "rho", "l", "span1", "chord1", "span2", "chord2", "U")
        for name in positive:
            value = getattr(self, name)
            require(math.isfinite(value) and value > 0, name, value, "must be finite and > 0")
        for name in ("l1", "l2", "l3", "l4", "CD0", "CDs", "cs"):
            value = getattr(self, name)
            require(math.isfinite(value) and value >= 0, name, value, "must be finite and >= 0")
        require(math.isfinite(self.xi0), "xi0", self.xi0, "must be finite (m)")
        require(math.isfinite(self.theta0) and abs(self.theta0) < math.pi / 4, "theta0",
                self.theta0, "must be finite with |theta0| < pi/4 rad")
        for name in ("alpha_stall", "alpha_max"):
            value = getattr(self, name)
            require(math.isfinite(value) and 0 < value < math.pi / 2, name, value,
                    "must be in (0, pi/2) rad")
        require(self.lift_slope in ("prandtl", "helmbold"), "lift_slope", self.lift_slope,
                "must be 'prandtl' or 'helmbold'")
        require(isinstance(self.added_mass, bool), "added_mass", self.added_mass,
                "must be True or False")

    @property
    def aspect_ratio(self) -> FloatArray:
        """Foil aspect ratios ``span/chord`` [front, rear], -."""
        return np.array([self.span1 / self.chord1, self.span2 / self.chord2])

    @property
    def area(self) -> FloatArray:
        """Foil planform areas ``span*chord`` [front, rear], m^2."""
        return np.array([self.span1 * self.chord1, self.span2 * self.chord2])

    @property
    def chord(self) -> FloatArray:
        """Foil chords [front, rear], m."""
        return np.array([self.chord1, self.chord2])

    @property
    def foil_x(self) -> FloatArray:
        """Foil positions along body +x from the CG [front, rear] = [+l1, -l2], m."""
        return np.array([self.l1, -self.l2])

    @property
    def lift_curve_slope(self) -> FloatArray:
        """3-D lift slope a_i [front, rear], 1/rad (Prandtl or Helmbold, per ``lift_slope``)."""
        ar = self.aspect_ratio
        if self.lift_slope == "helmbold":
            return 2 * np.pi * ar / (2 + np.sqrt(ar**2 + 4))
        return 2 * np.pi * ar / (ar + 2)

    @property
    def foil_added_mass(self) -> FloatArray:
        """Heave added mass ``rho*pi*(c/2)^2*b*AR/(1+AR)`` of each foil, kg  [PROPOSED formula]."""
        ar, span = self.aspect_ratio, np.array([self.span1, self.span2])
        return self.rho * np.pi * (self.chord / 2) ** 2 * span * ar / (1 + ar)


@dataclasses.dataclass(frozen=True, eq=False)
class HydrofoilTrim:
    """The trim (equilibrium) at ``(xi0, theta0)``, speed U, calm water (docs/models.md 2.3).
    Arrays are [front, rear].

    :param alpha_s0: foil angles, rad.
    :param F0: thrust, N.
    :param L: lift, N.
    :param C_L: lift coefficient, -.
    :param D: foil drag, N.
    :param f: strut drag, N.
    :param h: foil submergence, m.
    """

    alpha_s0: FloatArray
    F0: float
    L: FloatArray
    C_L: FloatArray
    D: FloatArray
    f: float
    h: FloatArray


#: Layout of the packed constants ``p`` of :func:`hydrofoil_rhs` (see :meth:`HydrofoilModel.pack`).
(X1, X2, A1, A2, HALF_A1, HALF_A2, K1, K2, QS1, QS2, INDUCED1, INDUCED2, STRUT, STRUT_L, SPEED,
 STALL, CD0, MASS, GRAVITY, ARM1, ARM2, ARM3, ARM4, THRUST) = range(24)
INV_MASS = 24  # the 2x2 inverse mass matrix, row by row
INERTIA, ADDED_MASS = 28, 29
#: The values :func:`hydrofoil_forces` returns: generalised forces, then their pieces per foil.
HEAVE, PITCH, LIFT, LIFT_COEFFICIENT, DRAG, STRUT_DRAG, SUBMERGENCE = 0, 1, 2, 4, 6, 8, 9


@jit
def hydrofoil_forces(x, u, d, p, thrust):
    """Heave force (N, down) and pitch moment (N m, bow-up) of one craft at thrust ``thrust``
    (N), and what they are made of, in the order of :data:`HEAVE` ...: lift, lift coefficient
    and drag per foil, strut drag, submergence per foil."""
    xi, theta, xi_dot, theta_dot = x[0], x[1], x[2], x[3]
    x1, x2 = p[X1], p[X2]
    sin, cos = np.sin(theta), np.cos(theta)
    depth = xi + p[STRUT_L] * cos
    h1 = depth - x1 * sin + d[2]
    h2 = depth - x2 * sin + d[3]
    U1, U2 = p[SPEED] - d[4], p[SPEED] - d[5]
    alpha_1 = _clip((xi_dot - x1 * theta_dot + d[0]) / U1 + theta + u[0], p[STALL])
    alpha_2 = _clip((xi_dot - x2 * theta_dot + d[1]) / U2 + theta + u[1], p[STALL])
    # a*k(h/c) = a - (a/2)/(1 + 8 (h/c)^2), the same k(r) = (1 + 16r^2)/(2 + 16r^2)
    C_L1 = (p[A1] - p[HALF_A1] / (1 + p[K1] * h1 * h1)) * alpha_1
    C_L2 = (p[A2] - p[HALF_A2] / (1 + p[K2] * h2 * h2)) * alpha_2
    q1 = p[QS1] * U1 * U1 if h1 > 0 else 0.0  # a broached foil (h <= 0) carries nothing
    q2 = p[QS2] * U2 * U2 if h2 > 0 else 0.0
    L1, L2 = q1 * C_L1, q2 * C_L2
    D1 = q1 * (p[CD0] + p[INDUCED1] * C_L1 * C_L1)
    D2 = q2 * (p[CD0] + p[INDUCED2] * C_L2 * C_L2)
    mean_depth = 0.5 * (h1 + h2)
    f = p[STRUT] * (0.0 if mean_depth < 0.0 else mean_depth)
    heave = p[MASS] * p[GRAVITY] - (L1 + L2) - thrust * sin
    pitch = p[ARM1] * L1 - p[ARM2] * L2 + p[ARM3] * thrust - p[STRUT_L] * (D1 + D2) - p[ARM4] * f
    return heave, pitch, L1, L2, C_L1, C_L2, D1, D2, f, h1, h2


@jit
def _clip(alpha, stall):
    """``alpha`` clipped to ``[-stall, stall]`` (NaN passes, as with ``np.clip``)."""
    if alpha < -stall:
        return -stall
    return stall if alpha > stall else alpha


@jit
def hydrofoil_rhs(x, u, d, p, out):
    """One craft's ``x_dot`` (docs/models.md 2.3); ``p`` packed by :meth:`HydrofoilModel.pack`."""
    # unpacked: indexing the tuple by a named constant costs as much as the forces
    heave, pitch, _, _, _, _, _, _, _, _, _ = hydrofoil_forces(x, u, d, p, p[THRUST])
    out[0], out[1] = x[2], x[3]
    if p[ADDED_MASS] != 0.0:
        i = INV_MASS
        out[2] = p[i] * heave + p[i + 1] * pitch
        out[3] = p[i + 2] * heave + p[i + 3] * pitch
    else:
        out[2], out[3] = heave / p[MASS], pitch / p[INERTIA]


@jit
def _forces_at(x, u, d, p, thrust):
    """:func:`hydrofoil_forces` as an array (for the trim)."""
    return np.array(hydrofoil_forces(x, u, d, p, thrust))


class HydrofoilModel(VehicleModel):
    """Heave/pitch of a fully-submerged two-foil craft at constant speed (the hydrofoil AKF paper).

    :param params: :class:`HydrofoilParams`; ``None`` for the paper's nominal craft.
    :raises ValueError: the parameters admit no trim with both foils submerged and unstalled.

    :ivar trim: the :class:`HydrofoilTrim`, solved at construction.
    """

    name: ClassVar[str] = "hydrofoil"
    state_names: ClassVar[tuple[str, ...]] = ("xi", "theta", "xi_dot", "theta_dot")
    input_names: ClassVar[tuple[str, ...]] = ("alpha_s1", "alpha_s2")
    disturbance_names: ClassVar[tuple[str, ...]] = (
        "zeta_dot_1", "zeta_dot_2", "eta_1", "eta_2", "u_w1", "u_w2")
    state_units: ClassVar[tuple[str, ...]] = ("m", "rad", "m/s", "rad/s")
    input_units: ClassVar[tuple[str, ...]] = ("rad", "rad")
    disturbance_units: ClassVar[tuple[str, ...]] = ("m/s", "m/s", "m", "m", "m/s", "m/s")
    is_linear: ClassVar[bool] = False
    equations: ClassVar[Equations] = Equations(hydrofoil_rhs)

    def __init__(self, params: HydrofoilParams | None = None) -> None:
        super().__init__(HydrofoilParams() if params is None else params)
        self._F0 = 0.0
        self.trim = self._solve_trim()
        self._F0 = self.trim.F0
        self.__dict__.pop("constants", None)  # packed before the trim thrust was known

    def pack(self) -> FloatArray:
        """The constants of :func:`hydrofoil_rhs`, derived once: it runs 8x per control step."""
        p = self.params
        if p.added_mass:
            ma = p.foil_added_mass
            xs = p.foil_x
            mass = np.array([[p.m + ma.sum(), -(ma * xs).sum()],
                             [-(ma * xs).sum(), p.J + (ma * xs**2).sum()]])
        else:
            mass = np.diag([p.m, p.J])
        a = p.lift_curve_slope
        return np.concatenate([
            p.foil_x, a, a / 2,
            8 / p.chord**2,  # 16 r^2 / 2 with r = h/c, 1/m^2
            0.5 * p.rho * p.area,  # dynamic pressure per U^2 x area, kg/m
            1 / (np.pi * p.aspect_ratio),  # induced drag factor
            [0.5 * p.rho * p.U**2 * p.CDs * p.cs,  # strut drag per m of depth, N/m
             p.l, p.U, p.alpha_stall, p.CD0, p.m, p.g, p.l1, p.l2, p.l3, p.l4, self._F0],
            # generalised forces [heave force (N), pitch moment (N m)] -> accelerations
            np.linalg.inv(mass).ravel(), [p.J, float(p.added_mass)]])

    # -- nominal operating point -------------------------------------------------------------
    @property
    def x0(self) -> FloatArray:
        """Trim state ``[xi0, theta0, 0, 0]`` (m, rad, m/s, rad/s)."""
        return np.array([self.params.xi0, self.params.theta0, 0.0, 0.0])

    @property
    def u0(self) -> FloatArray:
        """Trim foil angles ``alpha_s0`` (rad)."""
        return self.trim.alpha_s0.copy()

    @property
    def F0(self) -> float:
        """Trim thrust, held constant, N."""
        return self._F0

    @property
    def u_bounds(self) -> tuple[FloatArray, FloatArray]:
        """Foil rotation limits ``+-alpha_max`` (rad) on both foils."""
        a = self.params.alpha_max
        return np.array([-a, -a]), np.array([a, a])

    # -- dynamics ------------------------------------------------------------------------------
    # -- trim ----------------------------------------------------------------------------------
    def _solve_trim(self) -> HydrofoilTrim:
        """Foil angles and thrust holding ``(xi0, theta0)`` in calm water at speed U.

        Solves ``xi_ddot = theta_ddot = 0`` and ``F cos(theta0) = D_1 + D_2 + f`` for
        ``(alpha_s1, alpha_s2, F)`` with :func:`scipy.optimize.fsolve`.
        """
        p = self.params
        x0, d0 = self.x0, np.zeros(len(self.disturbance_names))
        h = p.xi0 + p.l * math.cos(p.theta0) - p.foil_x * math.sin(p.theta0)
        require(bool(np.all(h > 0)), "xi0", p.xi0,
                f"must keep both foils submerged at trim (h = {h.tolist()} m)")

        constants = self.pack()

        def residual(z: FloatArray) -> FloatArray:
            forces = _forces_at(x0, z[:2].copy(), d0, constants, z[2])
            drag = forces[DRAG] + forces[DRAG + 1] + forces[STRUT_DRAG]
            return np.array([forces[HEAVE], forces[PITCH], z[2] * math.cos(p.theta0) - drag])

        # initial guess: the weight shared by the foils in inverse ratio of their arms, no drag
        share = np.array([p.l2, p.l1]) / (p.l1 + p.l2) if p.l1 + p.l2 > 0 else np.full(2, 0.5)
        qS = 0.5 * p.rho * p.U**2 * p.area
        guess = np.append(p.m * p.g * share / (qS * p.lift_curve_slope) - p.theta0,
                          0.1 * p.m * p.g)
        from scipy.optimize import fsolve  # (here, not at import: it takes 0.2 s)

        z, _, ok, message = fsolve(residual, guess, xtol=1e-13, full_output=True)
        if ok != 1 or np.abs(residual(z)).max() > 1e-6 * p.m * p.g:
            # usually the foils stall before they carry the weight: too slow, small or heavy
            raise ValueError(f"no trim found for U={p.U!r} m/s, m={p.m!r} kg, alpha_stall="
                             f"{p.alpha_stall!r} rad: the unstalled foils cannot hold (xi0, "
                             f"theta0) ({' '.join(message.split())})")
        alpha = p.theta0 + z[:2]  # calm water, at rest: angle of attack = theta + alpha_s
        require(bool(np.all(np.abs(alpha) < p.alpha_stall)), "alpha_stall", p.alpha_stall,
                f"must exceed the trim angles of attack {alpha.tolist()} rad")
        require(bool(np.all(np.abs(z[:2]) <= p.alpha_max)), "alpha_max", p.alpha_max,
                f"must allow the trim foil angles {z[:2].tolist()} rad")
        forces = _forces_at(x0, z[:2].copy(), d0, constants, z[2])
        pair = lambda i: forces[i:i + 2].copy()  # noqa: E731
        return HydrofoilTrim(alpha_s0=z[:2].copy(), F0=float(z[2]), L=pair(LIFT),
                             C_L=pair(LIFT_COEFFICIENT), D=pair(DRAG),
                             f=float(forces[STRUT_DRAG]), h=pair(SUBMERGENCE))
