"""Hovercraft: LCAC-like 3-DOF MMG-separated manoeuvring model (the hovercraft EKF paper;
docs/models.md section 5).

``x = [u, v, r, north, east, psi]`` (m/s, m/s, rad/s, m, m, rad) = docs/models.md's
``[u, v, r, X_N, Y_E, psi]``; ``u = [sigma_1, sigma_2, delta]`` (-, -, rad): port and starboard
propeller pitch fractions in [-0.5, 1] and the air-rudder angle, ``|delta| <= 30 deg``;
``d = [wind_north, wind_east]`` (m/s): the wind velocity in NED, i.e. the direction the air moves
TO (a wind "from the north" has ``wind_north < 0``). Equations (docs/models.md 5.2, with its
corrections u|u|, v|v|, |delta| and the symmetric added mass Y_rd = N_vd)::

    (m - X_ud) u_dot                 = X_A + X_H + X_P + X_R + m v r
    (m - Y_vd) v_dot - Y_rd r_dot    = Y_A + Y_H + Y_R - m u r
    (Iz - N_rd) r_dot - N_vd v_dot   = N_A + N_H + N_R + N_P
    north_dot = u cos(psi) - v sin(psi),  east_dot = u sin(psi) + v cos(psi),  psi_dot = r

    X_A = X_Au u_a + X_Auu u_a|u_a| + X_Avv v_a^2 + X_Auv u_a v_a
    Y_A = Y_Av v_a + Y_Avv v_a|v_a| + Y_Auv u_a v_a
    N_A = N_Av v_a + N_Ar r + N_Avvv v_a^3 + N_Arrr r^3 + N_Avvr v_a^2 r + N_Avrr v_a r^2
    X_H = X_Hu u + X_Huu u|u| + X_Hvv v^2 + X_Huv u v
    Y_H = Y_Hv v + Y_Hvv v|v| + Y_Huv u v
    N_H = N_Hv v + N_Hr r + N_Hbeta beta + N_Hvvv v^3 + N_Hrrr r^3 + N_Hvvr v^2 r + N_Hvrr v r^2,
          beta = atan2(-v, u)
    T_i = T0 sigma_i (1 - u_a/U_T),  X_P = T_1 + T_2,  N_P = y_P (T_1 - T_2)   (1 = port)
    V_R^2 = u_a^2 + k_s 2 Tbar/(rho_a A_p),  Tbar = max(0, (T_1 + T_2)/2),  A_p = pi D_p^2/4
    q_R = rho_a V_R^2 / 2
    X_R = -n_R (C_R1 + C_R2|delta| + C_R3 delta^2) S_R q_R
    Y_R = -n_R C_R4 delta S_R q_R,  N_R = x_R Y_R

Wind (an extension docs/models.md leaves open; the choices are documented here). The air-relative
body velocities are ``u_a = u - (Vn cos psi + Ve sin psi)`` and
``v_a = v - (-Vn sin psi + Ve cos psi)``. The aerodynamic hull terms use them, and so do the
air-propeller thrust factor ``(1 - u_a/U_T)`` and the air-rudder inflow ``V_R``: propellers and
rudders work in air. The yaw-rate terms of N_A keep ``r`` (the wind is uniform). The hydrodynamic
(skirt/cushion) terms use the water-relative ``u, v`` (no current in this model). With zero wind
``u_a = u`` and the equations are those of docs/models.md 5.2.

Every coefficient is [PROPOSED] (docs/models.md 5.3): no numeric LCAC coefficient is public. Only
the mass scale (~150 t) and the rudder count n_R = 3 come from the hovercraft EKF paper [SEED].
"""

from __future__ import annotations

import dataclasses
import math
import numbers
from types import SimpleNamespace
from typing import Any, ClassVar

import numpy as np

from ..compiled import Equations, jit
from .base import FloatArray, VehicleModel, require
from .kinematics import planar_to_body, planar_to_ned

KNOT = 1852.0 / 3600.0  #: m/s per knot

#: Added-mass and inertia fields that default to a value derived from m, L and B (see
#: :meth:`HovercraftParams.resolved`), with their default factors.
_DERIVED = ("Iz", "X_ud", "Y_vd", "N_rd", "N_vd")


@dataclasses.dataclass(frozen=True)
class HovercraftParams:
    """Parameters of the hovercraft model; names are docs/models.md 5.3's symbols. SI units,
    radians.

    Derived defaults: ``Iz``, ``X_ud``, ``Y_vd``, ``N_rd`` and ``N_vd`` default to ``None``,
    meaning "derived from the mass and size": ``Iz = m (L^2 + B^2)/12``, ``X_ud = -0.02 m``,
    ``Y_vd = -0.05 m``, ``N_rd = -0.05 Iz``, ``N_vd = 0``. They stay ``None`` in the dataclass so
    that a variant with another ``m`` (``dataclasses.replace(p, m=1.8e5)``) re-derives them; give
    a number to override. :meth:`resolved` returns a copy with the numbers filled in.
    """

    # rigid body and added mass
    m: float = 1.50e5  #: mass, kg  [SEED: "~150 t"]
    Iz: float | None = None  #: yaw inertia, kg m^2; None = m(L^2+B^2)/12 = 1.1268e7  [PROPOSED]
    X_ud: float | None = None  #: surge added mass, kg; None = -0.02 m  [PROPOSED]
    Y_vd: float | None = None  #: sway added mass, kg; None = -0.05 m  [PROPOSED]
    N_rd: float | None = None  #: yaw added inertia, kg m^2; None = -0.05 Iz  [PROPOSED]
    N_vd: float | None = None  #: sway-yaw added mass (= Y_rd), kg m; None = 0  [PROPOSED]
    # aerodynamic hull forces (air-relative velocities u_a, v_a)
    X_Au: float = 0.0  #: N s/m  [PROPOSED]
    X_Auu: float = -24.5  #: kg/m (1/2 rho_a 80 m^2 C_D 0.5)  [PROPOSED]
    X_Avv: float = -10.0  #: kg/m  [PROPOSED]
    X_Auv: float = 0.0  #: kg/m  [PROPOSED]
    Y_Av: float = 0.0  #: N s/m  [PROPOSED]
    Y_Avv: float = -105.0  #: kg/m (1/2 rho_a 172 m^2 C_Dc 1.0)  [PROPOSED]
    Y_Auv: float = -84.0  #: kg/m (C_Ybeta 0.8)  [PROPOSED]
    N_Av: float = 1.0e4  #: N s (weak weathercock stability from the aft ducts)  [PROPOSED]
    N_Ar: float = -4.0e5  #: N m s  [PROPOSED]
    N_Avvv: float = 0.0  #: N s^3/m^2  [PROPOSED]
    N_Arrr: float = 0.0  #: N m s^3  [PROPOSED]
    N_Avvr: float = 0.0  #: N s^3/m  [PROPOSED]
    N_Avrr: float = 0.0  #: N s^3  [PROPOSED]
    # hydrodynamic (skirt, cushion momentum, wave-making) forces
    X_Hu: float = -1000.0  #: N s/m  [PROPOSED]
    X_Huu: float = -150.0  #: kg/m  [PROPOSED]
    X_Hvv: float = -300.0  #: kg/m  [PROPOSED]
    X_Huv: float = 0.0  #: kg/m  [PROPOSED]
    Y_Hv: float = -2.0e4  #: N s/m  [PROPOSED]
    Y_Hvv: float = -2000.0  #: kg/m  [PROPOSED]
    Y_Huv: float = -1500.0  #: kg/m  [PROPOSED]
    N_Hv: float = 0.0  #: N s  [PROPOSED]
    N_Hr: float = -2.0e6  #: N m s  [PROPOSED]
    N_Hbeta: float = 0.0  #: N m/rad (collinear with N_Hv v at fixed u, hence 0)  [PROPOSED]
    N_Hvvv: float = 0.0  #: N s^3/m^2  [PROPOSED]
    N_Hrrr: float = -5.0e8  #: N m s^3  [PROPOSED]
    N_Hvvr: float = -2.0e4  #: N s^3/m  [PROPOSED]
    N_Hvrr: float = 0.0  #: N s^3  [PROPOSED]
    # propellers (two shrouded reversible-pitch air propellers)
    T0: float = 80.0e3  #: static thrust per propeller at sigma = 1, N  [PROPOSED]
    U_T: float = 50.0  #: speed at which the thrust vanishes, m/s  [PROPOSED]
    D_p: float = 3.58  #: propeller diameter, m  [RECALLED: US Navy fact file]
    y_P: float = 4.6  #: propeller lateral offset from the centre line, m  [PROPOSED]
    sigma_min: float = -0.5  #: lowest pitch fraction (reverse), -  [PROPOSED]
    sigma_max: float = 1.0  #: highest pitch fraction, -  [PROPOSED]
    # air rudders in the slipstream
    #: number of rudders (the hovercraft EKF paper's factor "-3(...)"), -  [SEED, interpreted]
    n_R: float = 3.0
    S_R: float = 4.0  #: area of one rudder, m^2  [PROPOSED]
    x_R: float = -12.0  #: rudder position aft of the CG (negative), m  [PROPOSED]
    k_s: float = 0.5  #: fraction of the slipstream dynamic pressure on the rudders, -  [PROPOSED]
    C_R1: float = 0.02  #: rudder drag at zero angle, -  [PROPOSED]
    C_R2: float = 0.0  #: rudder drag per |rad|, 1/rad  [PROPOSED]
    C_R3: float = 1.5  #: rudder drag per rad^2, 1/rad^2  [PROPOSED]
    C_R4: float = 2.0  #: rudder lift slope, 1/rad  [PROPOSED]
    delta_max: float = math.radians(30.0)  #: rudder limit, rad  [PROPOSED]
    # environment and size
    rho_a: float = 1.225  #: air density, kg/m^3  [global convention]
    L: float = 26.4  #: length, m  [RECALLED: US Navy fact file]
    B: float = 14.3  #: beam, m  [RECALLED: US Navy fact file]
    u_cruise: float = 32.0 * KNOT  #: nominal cruise speed (32 kn = 16.462 m/s), m/s  [PROPOSED]

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if value is None and f.name in _DERIVED:
                continue
            require(isinstance(value, numbers.Real) and not isinstance(value, bool)
                    and math.isfinite(value), f.name, value, "must be a finite real number")
        for name in ("m", "T0", "U_T", "D_p", "S_R", "rho_a", "L", "B", "delta_max", "u_cruise",
                     "n_R"):
            value = getattr(self, name)
            require(value > 0, name, value, "must be > 0")
        require(self.Iz is None or self.Iz > 0, "Iz", self.Iz, "must be > 0 (or None: derived)")
        for name in ("y_P", "k_s", "C_R1", "C_R3"):
            value = getattr(self, name)
            require(value >= 0, name, value, "must be >= 0")
        require(self.x_R < 0, "x_R", self.x_R, "must be < 0 (rudders aft of the CG)")
        require(self.delta_max <= math.pi / 2, "delta_max", self.delta_max, "must be <= pi/2 rad")
        require(self.sigma_min < 0, "sigma_min", self.sigma_min, "must be < 0 (reverse pitch)")
        require(self.sigma_max > 0, "sigma_max", self.sigma_max, "must be > 0")
        require(self.u_cruise < self.U_T, "u_cruise", self.u_cruise,
                f"must be below the zero-thrust speed U_T={self.U_T}")
        r = self.resolved()
        # the mass matrix must be positive definite or the accelerations are meaningless
        require(r.m - r.X_ud > 0, "X_ud", self.X_ud, "need m - X_ud > 0")
        require(r.m - r.Y_vd > 0, "Y_vd", self.Y_vd, "need m - Y_vd > 0")
        require(r.Iz - r.N_rd > 0, "N_rd", self.N_rd, "need Iz - N_rd > 0")
        require((r.m - r.Y_vd) * (r.Iz - r.N_rd) - r.N_vd**2 > 0, "N_vd", self.N_vd,
                "need (m - Y_vd)(Iz - N_rd) > N_vd^2 (positive-definite sway-yaw mass)")

    def resolved(self) -> HovercraftParams:
        """A copy with the derived defaults (``Iz``, ``X_ud``, ``Y_vd``, ``N_rd``, ``N_vd``) filled
        in as numbers (kg, kg m^2, kg m)."""
        changes = self.derived()
        return dataclasses.replace(self, **changes) if changes else self

    def derived(self) -> dict[str, Any]:
        """The derived defaults that are ``None``, as numbers (kg, kg m^2, kg m): numpy
        arithmetic, so parameters held per batch row derive per row."""
        Iz = self.m * (self.L**2 + self.B**2) / 12.0 if self.Iz is None else self.Iz
        defaults = {"Iz": Iz, "X_ud": -0.02 * self.m, "Y_vd": -0.05 * self.m,
                    "N_rd": -0.05 * Iz, "N_vd": 0.0}
        return {k: v for k, v in defaults.items() if getattr(self, k) is None}


#: Layout of the packed constants ``p`` of :func:`hovercraft_rhs`: three sets of the 13
#: polynomial coefficients (see :meth:`HovercraftModel.pack`), then the other constants.
HYDRO, AERO, BOTH = 0, 13, 26
(INV_M11, INV_M, DISC, RUDDER, T0, THRUST_SLOPE, C_R1, C_R2, C_R3, C_R4, MASS, X_R, Y_P,
 N_HBETA) = 39, 40, 44, 45, 46, 47, 48, 49, 50, 51, 52, 53, 54, 55


@jit
def _polynomials(p, c, u, v, r):
    """The polynomial X, Y, N forces (N, N, N m) of the coefficient set at ``p[c:c + 13]``."""
    x_u, x_uu, x_vv, x_uv, y_v, y_vv, y_uv = p[c], p[c + 1], p[c + 2], p[c + 3], p[c + 4], \
        p[c + 5], p[c + 6]
    n_v, n_r, n_vvv, n_rrr, n_vvr, n_vrr = p[c + 7], p[c + 8], p[c + 9], p[c + 10], p[c + 11], \
        p[c + 12]
    uv = u * v
    vv = v * v
    x = (x_u + x_uu * abs(u)) * u + x_vv * vv + x_uv * uv
    y = (y_v + y_vv * abs(v)) * v + y_uv * uv
    n = n_v * v + n_r * r + (n_vvv * vv + (n_vvr * v + n_vrr * r) * r) * v + n_rrr * (r * r) * r
    return x, y, n


@jit
def hovercraft_rhs(x, u, d, p, out):
    """One craft's ``x_dot`` (module docstring); ``p`` packed by :meth:`HovercraftModel.pack`.
    Inputs are not clipped here: the environment applies the bounds."""
    vel_u, vel_v, r, psi = x[0], x[1], x[2], x[5]
    sigma_1, sigma_2, delta = u[0], u[1], u[2]
    c, s = np.cos(psi), np.sin(psi)
    if d[0] == 0.0 and d[1] == 0.0:  # u_a = u, v_a = v: one polynomial, summed coefficients
        ua = vel_u
        x_force, y_force, n_moment = _polynomials(p, BOTH, vel_u, vel_v, r)
    else:
        wind_u, wind_v = planar_to_body(c, s, d[0], d[1])
        ua, va = vel_u - wind_u, vel_v - wind_v
        x_force, y_force, n_moment = _polynomials(p, HYDRO, vel_u, vel_v, r)
        x_air, y_air, n_air = _polynomials(p, AERO, ua, va, r)
        x_force, y_force, n_moment = x_force + x_air, y_force + y_air, n_moment + n_air
    if p[N_HBETA] != 0.0:  # atan2 is costly and the default coefficient is 0
        n_moment = n_moment + p[N_HBETA] * np.arctan2(-vel_v, vel_u)
    thrust_factor = p[T0] - p[THRUST_SLOPE] * ua
    t1, t2 = sigma_1 * thrust_factor, sigma_2 * thrust_factor
    # rudder dynamic pressure times n_R S_R: free stream plus k_s of the slipstream increment
    q = p[RUDDER] * (ua * ua + p[DISC] * max(0.0, 0.5 * (t1 + t2)))
    y_r = (-p[C_R4] * q) * delta
    abs_delta = abs(delta)
    x_force = (x_force + (t1 + t2) + p[MASS] * vel_v * r
               - (p[C_R1] + (p[C_R2] + p[C_R3] * abs_delta) * abs_delta) * q)
    y_force = y_force + y_r - p[MASS] * vel_u * r
    n_moment = n_moment + p[X_R] * y_r + p[Y_P] * (t1 - t2)
    i = INV_M
    out[0] = x_force * p[INV_M11]
    out[1] = p[i] * y_force + p[i + 1] * n_moment
    out[2] = p[i + 2] * y_force + p[i + 3] * n_moment
    out[3], out[4] = planar_to_ned(c, s, vel_u, vel_v)
    out[5] = r


class HovercraftModel(VehicleModel):
    """LCAC-like air-cushion vehicle, 3-DOF MMG-separated model (the hovercraft EKF paper,
    docs/models.md 5).

    The nominal point is straight running at ``u_cruise`` (32 kn) with both pitches at the trim
    value :meth:`trim_pitch` and the rudder amidships.
    """

    name: ClassVar[str] = "hovercraft"
    state_names: ClassVar[tuple[str, ...]] = ("u", "v", "r", "north", "east", "psi")
    input_names: ClassVar[tuple[str, ...]] = ("sigma_1", "sigma_2", "delta")
    disturbance_names: ClassVar[tuple[str, ...]] = ("wind_north", "wind_east")
    state_units: ClassVar[tuple[str, ...]] = ("m/s", "m/s", "rad/s", "m", "m", "rad")
    input_units: ClassVar[tuple[str, ...]] = ("-", "-", "rad")
    disturbance_units: ClassVar[tuple[str, ...]] = ("m/s", "m/s")
    #: The force-polynomial and rudder coefficients: each multiplies one term of the forces.
    affine_parameters: ClassVar[frozenset[str]] = frozenset(
        f.name for f in dataclasses.fields(HovercraftParams)
        if f.name[:3] in ("X_A", "Y_A", "N_A", "X_H", "Y_H", "N_H") or f.name.startswith("C_R"))
    equations: ClassVar[Equations] = Equations(hovercraft_rhs)
    #: :meth:`pack` is numpy arithmetic: a parameter may hold one value per batch row.
    row_parameters: ClassVar[bool] = True
    #: Thrust, drags, yaw inertia and damping: the coefficients no craft states on paper (the
    #: EPFL runs' were fitted by equation error); mass, lever arm and size are weighed and
    #: measured, and the scale ambiguities (T0 m, y_P Iz) leave them out.
    calibration_candidates: ClassVar[tuple[str, ...]] = ("T0", "X_Hu", "Y_Hv", "Iz", "N_Hr")

    def __init__(self, params: HovercraftParams | None = None) -> None:
        super().__init__(HovercraftParams() if params is None else params)
        self._sigma0: float | None = None  # trim pitch at u_cruise, computed on first use

    def pack(self) -> FloatArray:
        """The constants of :func:`hovercraft_rhs`, derived once: it runs 8x per control step."""
        k = SimpleNamespace(**{**vars(self.params), **self.params.derived()})  # rows allowed
        hydro = (k.X_Hu, k.X_Huu, k.X_Hvv, k.X_Huv, k.Y_Hv, k.Y_Hvv, k.Y_Huv, k.N_Hv,
                 k.N_Hr + k.N_Ar, k.N_Hvvv, k.N_Hrrr + k.N_Arrr, k.N_Hvvr, k.N_Hvrr)
        # aerodynamic terms in (u_a, v_a, r); the r-only terms sit in `hydro` (r is the same)
        aero = (k.X_Au, k.X_Auu, k.X_Avv, k.X_Auv, k.Y_Av, k.Y_Avv, k.Y_Auv, k.N_Av, 0.0,
                k.N_Avvv, 0.0, k.N_Avvr, k.N_Avrr)
        both = tuple(h + a for h, a in zip(hydro, aero, strict=True))  # no wind: u_a = u
        # inverse of the sway-yaw mass matrix [[m - Y_vd, -Y_rd], [-N_vd, Iz - N_rd]], Y_rd = N_vd
        m22, m23, m32, m33 = k.m - k.Y_vd, -k.N_vd, -k.N_vd, k.Iz - k.N_rd
        det = m22 * m33 - m23 * m32
        inverse = (m33 / det, -m23 / det, -m32 / det, m22 / det)
        disc = k.k_s * 2.0 / (k.rho_a * math.pi * k.D_p**2 / 4.0)  # V_R^2 per N of Tbar
        rudder = k.n_R * k.S_R * 0.5 * k.rho_a  # force per (coefficient * V_R^2)
        packed = (*hydro, *aero, *both, 1.0 / (k.m - k.X_ud), *inverse, disc, rudder, k.T0,
                  k.T0 / k.U_T, k.C_R1, k.C_R2, k.C_R3, k.C_R4, k.m, k.x_R, k.y_P, k.N_Hbeta)
        return np.stack(np.broadcast_arrays(*packed), axis=-1).astype(float)

    # -- nominal operating point -------------------------------------------------------------
    @property
    def x0(self) -> FloatArray:
        """Straight running at the cruise speed: ``[u_cruise, 0, 0, 0, 0, 0]``."""
        return np.array([self.params.u_cruise, 0.0, 0.0, 0.0, 0.0, 0.0])

    @property
    def u0(self) -> FloatArray:
        """Trim pitch on both propellers at the cruise speed (0.598 nominal), rudder amidships."""
        if self._sigma0 is None:
            self._sigma0 = self.trim_pitch(self.params.u_cruise)
        return np.array([self._sigma0, self._sigma0, 0.0])

    def trim_point(self, speed: float) -> tuple[FloatArray, FloatArray]:
        """State and input ``(x, u)`` of straight running at ``speed`` (m/s), zero wind."""
        sigma = self.trim_pitch(speed)
        return np.array([speed, 0.0, 0.0, 0.0, 0.0, 0.0]), np.array([sigma, sigma, 0.0])

    def trim_pitch(self, speed: float) -> float:
        """Pitch fraction (-) on both propellers that holds ``speed`` (m/s) straight ahead with the
        rudder amidships and no wind (``u_dot = 0``).

        ``u_dot`` is piecewise linear in the common pitch sigma (the slipstream term uses
        ``max(0, T)``), so the root is exact on the branch of the sign of the required thrust.

        :raises ValueError: the speed needs a pitch outside ``[sigma_min, sigma_max]`` or is not
            below the zero-thrust speed ``U_T``.
        """
        k = self.params
        require(math.isfinite(speed) and abs(speed) < k.U_T, "speed", speed,
                f"must be finite with |speed| < U_T={k.U_T} m/s")
        x = np.array([speed, 0.0, 0.0, 0.0, 0.0, 0.0])

        def surge(sigma: float) -> float:
            return float(self.rhs(x, np.array([sigma, sigma, 0.0]))[0])

        f0 = surge(0.0)
        branch = 1.0 if f0 < 0 else -1.0  # drag needs forward thrust, and vice versa
        f1 = surge(branch)
        sigma = 0.0 if f0 == 0 else branch * f0 / (f0 - f1)
        require(k.sigma_min <= sigma <= k.sigma_max, "speed", speed,
                f"needs pitch {sigma:.3f}, outside [{k.sigma_min}, {k.sigma_max}]")
        return sigma

    @property
    def u_bounds(self) -> tuple[FloatArray, FloatArray]:
        k = self.params
        return (np.array([k.sigma_min, k.sigma_min, -k.delta_max]),
                np.array([k.sigma_max, k.sigma_max, k.delta_max]))
