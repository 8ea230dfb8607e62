"""MMG: 3-DOF manoeuvring model of a single-screw, single-rudder ship by the MMG standard method
(Yasukawa & Yoshimura 2015, "Introduction of MMG standard method for ship maneuvering
predictions", J Mar Sci Technol 20:37-52; docs/models.md section 8).

``x = [u, v, r, psi]`` (m/s, m/s, rad/s, rad): surge and sway velocity at MIDSHIP (the paper's
``u``, ``v_m``), yaw rate (positive turning to starboard) and heading; ``u = [delta, n_p]`` (rad,
rev/s): rudder angle in the HSVA records' convention (POSITIVE TO PORT, which gives a negative
r) and propeller speed; ``d = [w_r]`` (rad/s^2): a yaw acceleration added to ``r_dot``, as in
:mod:`.nomoto`. The paper's rudder angle is positive to starboard: the one place that maps it is
:func:`mmg_rhs` (``delta_mmg = -(delta + delta0)``; ``delta0`` is a rudder offset, the rudder
``-delta0`` holding a straight course). Equations (the paper's, as recalled)::

    (m + m_x) u_dot - (m + m_y) v r - x_G m r^2   = X_H + X_R + X_P
    (m + m_y) v_dot + (m + m_x) u r + x_G m r_dot = Y_H + Y_R
    (I_zG + x_G^2 m + J_z) r_dot + x_G m (v_dot + u r) = N_H + N_R          (+ w_r on r_dot)
    psi_dot = r

    U = sqrt(u^2 + v^2), v' = v/U, r' = r L/U, beta = atan2(-v, u)
    X_H = 1/2 rho L d U^2 (-R'_0 + X'_vv v'^2 + X'_vr v' r' + X'_rr r'^2 + X'_vvvv v'^4)
    Y_H = 1/2 rho L d U^2 (Y'_v v' + Y'_r r' + Y'_vvv v'^3 + Y'_vvr v'^2 r' + Y'_vrr v' r'^2
                           + Y'_rrr r'^3)
    N_H = 1/2 rho L^2 d U^2 (N'_v v' + N'_r r' + N'_vvv v'^3 + N'_vvr v'^2 r' + N'_vrr v' r'^2
                             + N'_rrr r'^3)
    X_P = (1 - t_P) rho n^2 D_p^4 K_T(J_P),  K_T = k0 + k1 J_P + k2 J_P^2,
    J_P = u (1 - w_P)/(n D_p),  beta_P = beta - x'_P r',
    1 - w_P = (1 - w_P0) (1 + (1 - exp(-C_1 |beta_P|)) (C_2 - 1)),  C_2 by the sign of beta_P
    X_R = -(1 - t_R) F_N sin(delta_mmg),  Y_R = -(1 + a_H) F_N cos(delta_mmg),
    N_R = -(x_R + a_H x_H) F_N cos(delta_mmg),  F_N = 1/2 rho A_R U_R^2 f_alpha sin(alpha_R)
    alpha_R = delta_mmg - atan2(v_R, u_R),  U_R^2 = u_R^2 + v_R^2
    u_R = eps sqrt(eta (u_P + kappa (sqrt(u_P^2 + 8 K_T (n D_p)^2/pi) - u_P))^2 + (1 - eta) u_P^2)
    u_P = (1 - w_P) u,  eta = D_p/H_R,  v_R = U gamma_R beta_R,  beta_R = beta - l'_R r',
    gamma_R by the sign of beta_R

(``u_P sqrt(1 + 8 K_T/(pi J_P^2))`` of the paper written as ``sqrt(u_P^2 + 8 K_T (n D_p)^2/pi)``,
which stays finite at J_P = 0.) The primed coefficients are the paper's non-dimensional ones
(forces by 1/2 rho L d U^2, moments by 1/2 rho L^2 d U^2, masses by 1/2 rho L^2 d, J_z by
1/2 rho L^4 d); the paper's ``Y'_R``, ``N'_R`` (yaw-rate derivatives) are ``Y_r``, ``N_r`` here.

Defaults: the paper's KVLCC2 model-scale (L = 7 m) coefficients (its tables of the model's
principal particulars and of the hydrodynamic force coefficients; the paper was not at hand:
the values are those transcribed identically by several public MMG implementations, e.g. the
ShipMMG/shipmmg project's KVLCC2_L7 fixture) with the HSVA model's main data
(``../shared/data/zigzag_kvlcc2_hsva/ship_data.yml``: the model the zigzag records come from);
where the two differ, the field's comment says so and which is used (docs/models.md 8.2).
"""

from __future__ import annotations

import dataclasses
import math
from typing import ClassVar

import numpy as np

from ..compiled import Equations, jit
from .base import FloatArray, VehicleModel, require

#: Layout of the packed constants ``p`` of :func:`mmg_rhs`: the 6 X, Y, N hull polynomial
#: coefficients each (X: -R_0, X_vv, X_vr, X_rr, X_vvvv, unused 0), then the other constants.
HULL_X, HULL_Y, HULL_N = 0, 6, 12
FORCE_SCALE, MOMENT_SCALE, LENGTH, INV_MX, MASS_Y, MASS_X, XG_M = range(18, 25)
INV_M = 25  # four entries: the inverse sway-yaw mass matrix, row by row
(PROP_SCALE, D_P, K0, K1, K2, ONE_MINUS_W0, C1, C2_POS, C2_NEG, X_P_DASH, ONE_MINUS_TR,
 ONE_PLUS_AH, RUDDER_ARM, RUDDER_SCALE, ETA, KAPPA, EPS, GAMMA_NEG, GAMMA_POS, L_R_DASH,
 OFFSET, TOW) = range(29, 51)
#: Below this speed, m/s, the non-dimensional hull polynomial (divided by U) is not evaluated.
_STILL = 1e-6


@jit
def _hull(p, c, v, r):
    """The polynomial ``a v + b r + c v^3 + d v^2 r + e v r^2 + f r^3`` of ``p[c:c + 6]``."""
    return ((p[c] + p[c + 2] * v * v) * v + (p[c + 1] + p[c + 5] * r * r) * r
            + (p[c + 3] * v + p[c + 4] * r) * v * r)


@jit
def mmg_rhs(x, u, d, p, out):
    """One ship's ``x_dot`` (module docstring); ``p`` packed by :meth:`MMGModel.pack`. Inputs are
    not clipped here: the environment applies the bounds."""
    vel_u, vel_v, r = x[0], x[1], x[2]
    delta = -(u[0] + p[OFFSET])  # the paper's rudder angle: positive to starboard
    n = u[1]
    speed = math.sqrt(vel_u * vel_u + vel_v * vel_v)
    if speed > _STILL:
        vd, rd = vel_v / speed, r * p[LENGTH] / speed
        beta = math.atan2(-vel_v, vel_u)
    else:
        vd, rd, beta = 0.0, 0.0, 0.0
    q = speed * speed
    x_hull = q * p[FORCE_SCALE] * (p[HULL_X] + (p[HULL_X + 1] + p[HULL_X + 4] * vd * vd) * vd * vd
                                   + (p[HULL_X + 2] * vd + p[HULL_X + 3] * rd) * rd)
    y_hull = q * p[FORCE_SCALE] * _hull(p, HULL_Y, vd, rd)
    n_hull = q * p[MOMENT_SCALE] * _hull(p, HULL_N, vd, rd)
    # propeller: wake by the inflow angle at the propeller, thrust by the open-water K_T
    beta_p = beta - p[X_P_DASH] * rd
    c2 = p[C2_POS] if beta_p > 0 else p[C2_NEG]
    u_p = vel_u * p[ONE_MINUS_W0] * (1.0 + (1.0 - math.exp(-p[C1] * abs(beta_p))) * (c2 - 1.0))
    nd = n * p[D_P]
    if nd > 0:
        j = u_p / nd
        k_t = p[K0] + (p[K1] + p[K2] * j) * j
    else:
        k_t = 0.0
    thrust = p[PROP_SCALE] * k_t * nd * nd  # (1 - t_P) rho n^2 D_p^4 K_T
    # rudder: inflow from the propeller slipstream and the hull's flow straightening
    jet = math.sqrt(max(u_p * u_p + 8.0 / math.pi * k_t * nd * nd, 0.0))
    accelerated = u_p + p[KAPPA] * (jet - u_p)
    u_r = p[EPS] * math.sqrt(p[ETA] * accelerated * accelerated + (1.0 - p[ETA]) * u_p * u_p)
    beta_r = beta - p[L_R_DASH] * rd
    v_r = speed * (p[GAMMA_POS] if beta_r > 0 else p[GAMMA_NEG]) * beta_r
    alpha = delta - math.atan2(v_r, u_r)
    normal = p[RUDDER_SCALE] * (u_r * u_r + v_r * v_r) * math.sin(alpha)
    cos_d = math.cos(delta)
    x_force = x_hull + thrust + p[TOW] - p[ONE_MINUS_TR] * normal * math.sin(delta) \
        + p[MASS_Y] * vel_v * r + p[XG_M] * r * r
    y_force = y_hull - p[ONE_PLUS_AH] * normal * cos_d - p[MASS_X] * vel_u * r
    n_moment = n_hull - p[RUDDER_ARM] * normal * cos_d - p[XG_M] * vel_u * r
    i = INV_M
    out[0] = x_force * p[INV_MX]
    out[1] = p[i] * y_force + p[i + 1] * n_moment
    out[2] = p[i + 2] * y_force + p[i + 3] * n_moment + d[0]
    out[3] = r


@dataclasses.dataclass(frozen=True)
class MMGParams:
    """Parameters of the MMG model: SI units, radians; primed (non-dimensional) coefficients as
    in the paper (module docstring). Sources: [YY] Yasukawa & Yoshimura 2015, KVLCC2 at
    L = 7 m; [HSVA] ship_data.yml of the HSVA free-running model."""

    # main data
    L: float = 7.0  #: length between perpendiculars, m  [YY = HSVA]
    d: float = 0.455  #: draught, m  [HSVA; YY 0.46]
    m: float = 3272.0  #: mass, kg  [HSVA (rho V, V = 3.27 m^3); YY the same volume]
    #: centre of gravity forward of midship, m  [HSVA; YY 0.25]
    x_G: float = 0.2436
    #: yaw moment of inertia about the CG, kg m^2  [HSVA (k_zz = 0.2486 L); YY k_zz = 0.25 L]
    I_zG: float = 9908.58
    rho: float = 1000.0  #: water density, kg/m^3  [HSVA, fresh tank water]
    # added masses (non-dimensional)  [YY]
    m_x: float = 0.022  #: surge added mass m'_x, -
    m_y: float = 0.223  #: sway added mass m'_y, -
    J_z: float = 0.011  #: yaw added moment of inertia J'_z, -
    # hull forces (non-dimensional)  [YY]
    R_0: float = 0.022  #: straight-running resistance coefficient R'_0, -
    X_vv: float = -0.040
    X_vr: float = 0.002
    X_rr: float = 0.011
    X_vvvv: float = 0.771
    Y_v: float = -0.315
    Y_r: float = 0.083  #: the paper's Y'_R
    Y_vvv: float = -1.607
    Y_vvr: float = 0.379
    Y_vrr: float = -0.391
    Y_rrr: float = 0.008
    N_v: float = -0.137
    N_r: float = -0.049  #: the paper's N'_R (linear yaw damping)
    N_vvv: float = -0.030
    N_vvr: float = -0.294
    N_vrr: float = 0.055
    N_rrr: float = -0.013
    # propeller
    #: propeller diameter, m  [YY 0.216 (= the full-scale 9.86 m / 45.7); HSVA's file says
    #: 0.204, but with YY's K_T curve 0.204 gives 33.3 N at the records' approach (1.179 m/s,
    #: 10.23 rev/s) where they measure 41.6 N thrust, and 0.216 gives 43.5 N: YY's used]
    D_p: float = 0.216
    k0: float = 0.2931  #: K_T = k0 + k1 J + k2 J^2  [YY]
    k1: float = -0.2753  #: [YY]
    k2: float = -0.1385  #: [YY]
    #: thrust deduction factor, -  [YY 0.220; HSVA's file says 0.25 citing YY: YY's value kept]
    t_P: float = 0.220
    #: skin-friction correction: a constant forward force on the model, N, as free-running
    #: model tests apply to run at the full-scale ship's propeller loading. 14.8 N makes the
    #: records' approach (1.179 m/s at 10.23 rev/s) steady: YY's resistance (R'_0: 48.7 N)
    #: minus the net thrust (1 - t_P) 43.5 N; the ITTC-57 friction lines give about 20 N for this
    #: model (wetted surface ~17 m^2, C_F model - ship ~ 0.0017). 0 = the model's own propulsion
    #: point (11.8 rev/s at 1.179 m/s).  [fitted to the records' approach, see above]
    X_sfc: float = 14.8
    w_P0: float = 0.40  #: wake fraction in straight running, -  [YY = HSVA]
    C_1: float = 2.0  #: wake change with beta_P, -  [YY = HSVA]
    C_2_pos: float = 1.6  #: C_2 for beta_P > 0, -  [YY = HSVA]
    C_2_neg: float = 1.1  #: C_2 for beta_P < 0, -  [YY = HSVA]
    #: propeller position, fraction of L (midship origin), -  [HSVA -3.386 m; YY -0.48 (other
    #: transcriptions say -0.65 or -0.69); HSVA's used]
    x_P: float = -3.386 / 7.0
    # rudder
    A_R: float = 0.0539  #: rudder area, m^2  [YY = HSVA]
    H_R: float = 0.345  #: rudder span, m  [YY = HSVA]
    f_alpha: float = 2.747  #: rudder lift gradient, 1/rad  [YY]
    t_R: float = 0.387  #: steering resistance deduction, -  [YY]
    a_H: float = 0.312  #: rudder force increase factor (hull), -  [YY]
    x_H: float = -0.464  #: position of the hull's extra lateral force, fraction of L  [YY]
    x_R: float = -0.5  #: rudder position, fraction of L  [YY = HSVA (-3.5 m)]
    eps: float = 1.09  #: wake ratio rudder/propeller epsilon, -  [YY]
    kappa: float = 0.50  #: propeller-slipstream factor, -  [YY]
    gamma_R_neg: float = 0.395  #: flow straightening for beta_R < 0, -  [YY]
    gamma_R_pos: float = 0.640  #: flow straightening for beta_R > 0, -  [YY]
    l_R: float = -0.710  #: effective rudder position for the flow straightening l'_R, -  [YY]
    #: rudder offset, rad (HSVA sign): the rudder -delta0 holds a straight course
    delta0: float = 0.0  # [PROPOSED: symmetric ship]
    delta_max: float = math.radians(35.0)  #: rudder limit, rad  [HSVA tests use +-35 deg]
    n_max: float = 20.0  #: highest propeller speed, rev/s  [PROPOSED: about 2x the test's]
    # nominal point: the HSVA zigzags' approach
    U_0: float = 1.179  #: approach speed, m/s  [HSVA: Fn 0.142]
    n_0: float = 10.23  #: propeller speed of the tests, rev/s  [HSVA]

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            require(isinstance(value, (int, float)) and not isinstance(value, bool)
                    and math.isfinite(value), f.name, value, "must be a finite real number")
        for name in ("L", "d", "m", "I_zG", "rho", "D_p", "A_R", "H_R", "f_alpha", "eps",
                     "delta_max", "n_max", "U_0", "n_0", "C_1", "C_2_pos", "C_2_neg"):
            require(getattr(self, name) > 0, name, getattr(self, name), "must be > 0")
        for name in ("m_x", "m_y", "J_z", "R_0", "kappa", "gamma_R_neg", "gamma_R_pos", "a_H"):
            require(getattr(self, name) >= 0, name, getattr(self, name), "must be >= 0")
        for name in ("t_P", "w_P0", "t_R"):
            require(0 <= getattr(self, name) < 1, name, getattr(self, name), "must be in [0, 1)")
        require(self.k0 > 0, "k0", self.k0, "must be > 0 (thrust at J = 0)")
        require(self.D_p < self.H_R, "D_p", self.D_p, f"must be < H_R={self.H_R} (eta < 1)")
        for name in ("x_P", "x_R"):
            require(-0.5 - 0.1 <= getattr(self, name) < 0, name, getattr(self, name),
                    "must be aft of midship, within 0.6 L (fraction of L)")
        require(abs(self.x_G) < 0.1 * self.L, "x_G", self.x_G, "must be within 0.1 L of midship")
        require(self.delta_max <= math.radians(45.0), "delta_max", self.delta_max,
                "must be <= 45 deg (in rad)")
        require(abs(self.delta0) < self.delta_max, "delta0", self.delta0,
                f"must be smaller than delta_max={self.delta_max}")
        require(self.n_0 <= self.n_max, "n_0", self.n_0, f"must be <= n_max={self.n_max}")


class MMGModel(VehicleModel):
    """3-DOF MMG manoeuvring model of the KVLCC2 tanker (module docstring), the host model for
    manoeuvres; :mod:`.nomoto` is the simple one."""

    name: ClassVar[str] = "mmg"
    state_names: ClassVar[tuple[str, ...]] = ("u", "v", "r", "psi")
    input_names: ClassVar[tuple[str, ...]] = ("delta", "n_p")
    disturbance_names: ClassVar[tuple[str, ...]] = ("w_r",)
    state_units: ClassVar[tuple[str, ...]] = ("m/s", "m/s", "rad/s", "rad")
    input_units: ClassVar[tuple[str, ...]] = ("rad", "rev/s")
    disturbance_units: ClassVar[tuple[str, ...]] = ("rad/s^2",)
    #: A free-running zigzag's channels: yaw rate and heading (the speeds where measured).
    measured_names: ClassVar[tuple[str, ...]] = ("r", "psi")
    #: Hull polynomial coefficients: each multiplies one term of the forces.
    affine_parameters: ClassVar[frozenset[str]] = frozenset(
        {"R_0", "X_vv", "X_vr", "X_rr", "X_vvvv", "Y_v", "Y_r", "Y_vvv", "Y_vvr", "Y_vrr",
         "Y_rrr", "N_v", "N_r", "N_vvv", "N_vvr", "N_vrr", "N_rrr"})
    #: Calibrated on zigzags (the rudder's lift gradient and the linear yaw damping): the two
    #: the benchmark's class validation chose before any held-out comparison (besides delta0,
    #: which differs from run to run).
    calibration_candidates: ClassVar[tuple[str, ...]] = ("f_alpha", "N_r")
    equations: ClassVar[Equations] = Equations(mmg_rhs)

    def __init__(self, params: MMGParams | None = None) -> None:
        super().__init__(MMGParams() if params is None else params)

    def pack(self) -> FloatArray:
        """The constants of :func:`mmg_rhs`, dimensional where the equations need them."""
        k = self.params
        force = 0.5 * k.rho * k.L * k.d
        moment = force * k.L
        m_x, m_y = force * k.L * k.m_x, force * k.L * k.m_y
        j_z = moment * k.L**2 * k.J_z
        # inverse of the sway-yaw mass matrix [[m + m_y, x_G m], [x_G m, I_zG + x_G^2 m + J_z]]
        a, b, c = k.m + m_y, k.x_G * k.m, k.I_zG + k.x_G**2 * k.m + j_z
        det = a * c - b * b
        hull = (-k.R_0, k.X_vv, k.X_vr, k.X_rr, k.X_vvvv, 0.0,
                k.Y_v, k.Y_r, k.Y_vvv, k.Y_vvr, k.Y_vrr, k.Y_rrr,
                k.N_v, k.N_r, k.N_vvv, k.N_vvr, k.N_vrr, k.N_rrr)
        return np.array([
            *hull, force, moment, k.L, 1.0 / (k.m + m_x), k.m + m_y, k.m + m_x, k.x_G * k.m,
            c / det, -b / det, -b / det, a / det,
            (1 - k.t_P) * k.rho * k.D_p**2, k.D_p, k.k0, k.k1, k.k2, 1 - k.w_P0, k.C_1,
            k.C_2_pos, k.C_2_neg, k.x_P, 1 - k.t_R, 1 + k.a_H, (k.x_R + k.a_H * k.x_H) * k.L,
            0.5 * k.rho * k.A_R * k.f_alpha, k.D_p / k.H_R, k.kappa, k.eps, k.gamma_R_neg,
            k.gamma_R_pos, k.l_R, k.delta0, k.X_sfc], dtype=float)

    # -- nominal operating point -------------------------------------------------------------
    @property
    def x0(self) -> FloatArray:
        """Straight running at the approach speed: ``[U_0, 0, 0, 0]``."""
        return np.array([self.params.U_0, 0.0, 0.0, 0.0])

    @property
    def u0(self) -> FloatArray:
        """The straight-course rudder ``-delta0`` and the tests' propeller speed ``n_0``."""
        return np.array([-self.params.delta0, self.params.n_0])

    @property
    def u_bounds(self) -> tuple[FloatArray, FloatArray]:
        k = self.params
        return np.array([-k.delta_max, 0.0]), np.array([k.delta_max, k.n_max])

    def trim_point(self, speed: float) -> tuple[FloatArray, FloatArray]:
        """State and input ``(x, u)`` of straight running at ``speed`` (m/s): the rudder
        ``-delta0`` and the propeller speed :meth:`self_propulsion` that balances the
        resistance."""
        return (np.array([speed, 0.0, 0.0, 0.0]),
                np.array([-self.params.delta0, self.self_propulsion(speed)]))

    def self_propulsion(self, speed: float) -> float:
        """Propeller speed (rev/s) at which the thrust balances the resistance in straight
        running at ``speed`` (m/s), rudder at ``-delta0``.

        The surge force is quadratic in n at fixed speed (thrust ``(1 - t_P) rho D_p^4 (k0 n^2
        + k1 n u_P/D_p + k2 u_P^2/D_p^2)``), so the positive root is exact.

        :raises ValueError: the speed is not positive or needs more than ``n_max``.
        """
        k = self.params
        require(math.isfinite(speed) and speed > 0, "speed", speed, "must be finite and > 0 m/s")
        x = np.array([speed, 0.0, 0.0, 0.0])

        def surge(n: float) -> float:
            return float(self.rhs(x, np.array([-k.delta0, n]))[0])

        # surge(n) = a n^2 + b n + c exactly for n > 0 (the rudder's normal force vanishes at
        # the straight-course rudder); a parabola through n = 1, 2, 3 rev/s
        f1, f2, f3 = surge(1.0), surge(2.0), surge(3.0)
        a = (f3 - 2 * f2 + f1) / 2
        b = f2 - f1 - 3 * a
        c = f1 - a - b
        disc = b * b - 4 * a * c
        require(a > 0 and disc >= 0, "speed", speed, "has no propeller speed that balances it")
        n = (-b + math.sqrt(disc)) / (2 * a)
        require(0 < n <= k.n_max, "speed", speed, f"needs n_p={n:.3g} rev/s, outside (0, n_max]")
        return n
