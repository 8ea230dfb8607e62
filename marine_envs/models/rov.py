"""ROV/AUV with a morphing hull, Prestero REMUS-100 coefficients (the morphing-robot patent;
docs/models.md section 3).

Six-degree-of-freedom rigid body with the body origin at the centre of buoyancy (CB), SNAME/NED
axes (x forward, y starboard, z down), ZYX Euler angles. ``x = [u v w p q r  x y z  phi theta psi
s]``: body velocities nu (m/s, rad/s), NED position (m, z down), Euler angles (rad) and the morph
fraction ``s`` (0 = cruise, 1 = work shape, manipulator deployed at the bow). ``u = tau = [X Y Z K
M N]``: generalised forces at the CB (N, N m). ``d = [current_n current_e current_d s_cmd]``: a
constant, irrotational ocean current in NED (m/s) and the morph command (-). docs/models.md 3.2::

    (M_RB(s) + M_A) nu_dot = -C_RB(nu, s) nu + tau_hyd(nu_r, s) + tau_s(eta, s) + tau
                             - M_A [w x nu_c; 0]          (current only, see "Current")
    eta_dot = J(eta) nu                     (ZYX Euler kinematics, NED position from nu)
    s_dot   = (s_cmd - s) / T_m

    M_RB = [[m I3, -m S(r_G)], [m S(r_G), I_b]],   I_b = diag(Ixx, Iyy, Izz) about the CB
    M_A  = -[[Xud,0,0,0,0,0], [0,Yvd,0,0,0,Yrd], [0,0,Zwd,0,Zqd,0],
             [0,0,0,Kpd,0,0], [0,0,Mwd,0,Mqd,0], [0,Nvd,0,0,0,Nrd]]
    -C_RB nu = [-m (w x nu1 + w x (w x r_G)) ;  -m r_G x (w x nu1) - w x (I_b w)],  w = [p q r]
        (Fossen's C_RB parameterisation independent of the linear velocity; no C_A: the
        added-mass Coriolis/Munk terms are already inside Prestero's combined coefficients)

    tau_hyd (Prestero's combined coefficients, on nu_r = [u_r v_r w_r p q r]):
    X = Xuu u|u| + Xwq w q + Xqq q q + Xvr v r + Xrr r r
    Y = Yvv v|v| + Yrr r|r| + Yuv u v + Ywp w p + Yur u r + Ypq p q
    Z = Zww w|w| + Zqq q|q| + Zuw u w + Zvp v p + Zuq u q + Zrp r p
    K = Kpp p|p|
    M = Mww w|w| + Mqq q|q| + Muw u w + Muq u q + Mvp v p + Mrp r p
    N = Nvv v|v| + Nrr r|r| + Nuv u v + Nur u r + Nwp w p + Npq p q

    tau_s (restoring; g = r_G W - r_B B):
    X_s = -(W-B) sin(theta)          K_s = g_y cos(theta) cos(phi) - g_z cos(theta) sin(phi)
    Y_s =  (W-B) cos(theta) sin(phi) M_s = -g_z sin(theta) - g_x cos(theta) cos(phi)
    Z_s =  (W-B) cos(theta) cos(phi) N_s =  g_x cos(theta) sin(phi) + g_y sin(theta)

Parameters, the work shape and the thrusters: :mod:`marine_envs.models.rov_params`.

**Current.** ``nu_r = nu - [nu_c; 0 0 0]``, ``nu_c = R(eta)^T v_c`` with ``v_c`` the NED current,
assumed constant and irrotational. The hydrodynamic terms act on the velocity through the water
``nu_r``; the rigid-body terms and the kinematics on ``nu`` (velocity over ground). The added-mass
inertia accelerates the water-relative motion, ``M_A nu_r_dot = M_A nu_dot + M_A [w x nu_c; 0]``
(``nu_c_dot = -w x nu_c``), which is Fossen's relative-velocity form, exact for such a current
(``current_inertia="relative"``, the default). The simpler approximation ``M_A nu_dot``
(``current_inertia="ground"``) drops the force ``-M_A [w x nu_c; 0]``; it is not energy-consistent:
a drifting boat that turns in the current gains relative speed again instead of settling.

**Implementation.** The equations of one boat are :func:`rov_rhs`, compiled
(:mod:`marine_envs.compiled`); ``rhs`` runs them on every row of a batch and the environment's
step kernel integrates them. The forces are linear in a feature vector ``F`` of products
(``u|u|``, ``w q``, ``sin(theta)``, ``tau``, ...), ``tau_total = C_0^T F + s dC^T F_morph``
(:func:`rov_features`, written once for the forces, the identification's regressors and the
right-hand side). ``M(s) = M_0 + s dM`` is inverted exactly for every ``s`` through the
generalised eigen-decomposition ``dM V = M_0 V diag(lam)``, ``V^T M_0 V = I``:
``M(s)^-1 = V diag(1 / (1 + s lam)) V^T``. With ``V^T`` folded into the coefficients, ``nu_dot``
costs a (12 x 41) product, a scaling and a 6x6 product (one 6-row product with ``M_0^-1`` folded
in when the hull is in cruise shape). Without a current the hydrodynamic and rigid-body
``omega nu`` products coincide and are folded together.

**Identification** (the morphing-robot patent). :data:`SEED_COEFFICIENTS` are the 18 viscous
coefficients the patent identifies online. ``tau_hyd`` is linear in every coefficient:
:meth:`ROVModel.hydrodynamic_regressors` gives its exact regressor ``Phi``;
:meth:`ROVModel.rhs_with` takes a coefficient's value AT THE CURRENT SHAPE (what an online
identifier sees) and is ``rhs(x, u + Phi (theta - c(s)), d)``;
:meth:`ROVModel.parameter_jacobian` is the exact ``[M(s)^-1 Phi; 0]``.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping, Sequence
from typing import ClassVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..compiled import Equations, evaluate, jit, local_array, rows
from .base import CompiledParameters, FloatArray, VehicleModel, require
from .kinematics import body_to_ned, euler_rates, ned_to_body, skew
from .rov_coefficients import coefficient_parameters
from .rov_params import (
    HYDRO_COEFFICIENTS,
    MORPHING,
    SEED_COEFFICIENTS,
    THRUSTER_ALLOCATION,
    THRUSTER_DIRECTIONS,
    THRUSTER_LIMITS,
    THRUSTER_POSITIONS,
    ROVParams,
    added_mass,
    allocate,
    mass_matrix,
    thruster_box,
)


def _cross_map() -> FloatArray:
    """(9, 3) map from the products ``a_i b_j`` (row 3 i + j) to ``a x b``."""
    eps = np.zeros((3, 3, 3))
    eps[0, 1, 2] = eps[1, 2, 0] = eps[2, 0, 1] = 1.0
    eps[0, 2, 1] = eps[2, 1, 0] = eps[1, 0, 2] = -1.0
    return eps.transpose(1, 2, 0).reshape(9, 3)


_CROSS = _cross_map()


# -- feature layout of the batched right-hand side (rows of F, one column per boat) ------------
_OMR = slice(0, 9)  # omega_i nu_r_j at row 3 i + j (i: p q r; j: u v w): hydrodynamic
_UV, _UW = 9, 10  # u_r v_r, u_r w_r
_TAU = slice(11, 17)  # X Y Z K M N
_ABS = slice(17, 23)  # u_r|u_r|, v_r|v_r|, w_r|w_r|, p|p|, q|q|, r|r|
_OMN = slice(23, 32)  # omega_i nu_j at row 23 + 3 i + j: rigid-body Coriolis, over ground
_ANG = slice(32, 38)  # p p, q q, r r, p q, p r, q r
_RES = slice(38, 41)  # sin(theta), cos(theta) sin(phi), cos(theta) cos(phi)
_MORPH = slice(17, 41)  # features whose coefficients change with s
_STILL = slice(9, 41)  # features used in still water, where omega nu_r = omega nu (OMR folded)
_N_FEATURES = 41
_PAIRS = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))
_X, _Y, _Z, _K, _M, _N = range(6)
_AB, _AN = _ABS.start, _ANG.start
#: coefficient -> (feature row of F, force component) of its single term in tau_hyd
_HYDRO_ENTRIES: dict[str, tuple[int, int]] = {
    "Xuu": (_AB, _X), "Yvv": (_AB + 1, _Y), "Nvv": (_AB + 1, _N), "Zww": (_AB + 2, _Z),
    "Mww": (_AB + 2, _M), "Kpp": (_AB + 3, _K), "Zqq": (_AB + 4, _Z), "Mqq": (_AB + 4, _M),
    "Yrr": (_AB + 5, _Y), "Nrr": (_AB + 5, _N),
    "Yuv": (_UV, _Y), "Nuv": (_UV, _N), "Zuw": (_UW, _Z), "Muw": (_UW, _M),
    "Zvp": (1, _Z), "Mvp": (1, _M), "Ywp": (2, _Y), "Nwp": (2, _N),  # p v_r, p w_r
    "Zuq": (3, _Z), "Muq": (3, _M), "Xwq": (5, _X),  # q u_r, q w_r
    "Yur": (6, _Y), "Nur": (6, _N), "Xvr": (7, _X),  # r u_r, r v_r
    "Xqq": (_AN + 1, _X), "Xrr": (_AN + 2, _X), "Ypq": (_AN + 3, _Y), "Npq": (_AN + 3, _N),
    "Zrp": (_AN + 4, _Z), "Mrp": (_AN + 4, _M),
}


def _coefficient_matrix(k: ROVParams, c: dict[str, float]) -> FloatArray:
    """(41, 6) matrix C with tau_total = C^T F for the shape ``c`` (affine in ``c``)."""
    C = np.zeros((_N_FEATURES, 6))
    ang = _ANG.start
    for name, (row, col) in _HYDRO_ENTRIES.items():
        C[row, col] = c[name]
    # rigid-body Coriolis, part linear in nu1: a = omega x nu1
    r_G = np.array([c["xG"], c["yG"], c["zG"]])
    C[_OMN, :3] = -k.m * _CROSS  # -m omega x nu1
    C[_OMN, 3:] = -k.m * _CROSS @ skew(r_G).T  # -m r_G x (omega x nu1)
    # rigid-body Coriolis, part quadratic in omega: split exactly into the monomials of _ANG
    inertia = np.array([c["Ixx"], c["Iyy"], c["Izz"]])

    def quad(om: FloatArray) -> FloatArray:
        return np.concatenate([-k.m * np.cross(om, np.cross(om, r_G)),
                               -np.cross(om, inertia * om)])

    unit = np.eye(3)
    for row, (i, j) in enumerate(_PAIRS, start=ang):
        C[row] += quad(unit[i]) if i == j else \
            quad(unit[i] + unit[j]) - quad(unit[i]) - quad(unit[j])
    # restoring forces, g = r_G W - r_B B
    wb = k.W - k.B
    gx, gy, gz = r_G * k.W - np.array([c["xB"], c["yB"], c["zB"]]) * k.B
    res = _RES.start
    C[res, [_X, _M, _N]] = -wb, -gz, gy
    C[res + 1, [_Y, _K, _N]] = wb, -gz, gx
    C[res + 2, [_Z, _K, _M]] = wb, gy, -gx
    C[_TAU] = np.eye(6)
    return C


def _shape_free(hydro: Mapping[str, ArrayLike],
                other: Mapping[str, ArrayLike]) -> dict[str, ArrayLike]:
    """Parameters for the generic ``rhs_with``: a coefficient's value at the current shape is
    the same cruise and work value (then ``c(s)`` is that value for every ``s``)."""
    clash = [f"work_{n}" for n in hydro if f"work_{n}" in other]
    if clash:
        raise ValueError(f"params give both {clash} and the coefficient at the current shape; "
                         "give one of them")
    both = dict(other)
    for name, value in hydro.items():
        both[name] = value
        if name in MORPHING:
            both[f"work_{name}"] = value
    return both


@functools.lru_cache(maxsize=64)
def _hydro_layout(names: tuple[str, ...]) -> tuple[NDArray[np.intp], FloatArray]:
    """``(features, select)`` of the coefficients ``names``: the feature row of each one's term
    and the (p, 6) map from terms to force rows."""
    unknown = [n for n in names if n not in _HYDRO_ENTRIES]
    if unknown:
        raise ValueError(f"unknown hydrodynamic coefficient(s) {unknown}; known: "
                         f"{', '.join(HYDRO_COEFFICIENTS)}")
    features = np.array([_HYDRO_ENTRIES[n][0] for n in names], dtype=np.intp)
    select = np.zeros((len(names), 6))
    select[np.arange(len(names)), [_HYDRO_ENTRIES[n][1] for n in names]] = 1.0
    return features, select


# -- the equations of one boat, compiled ------------------------------------------------------
#: Layout of the packed constants ``p`` of :func:`rov_rhs` (see :meth:`ROVModel.pack`): the
#: stacked [A; B] (12 x features) and P (6 x features) maps of the module docstring, with a
#: current (every feature) and in still water (the features of _STILL), then V, lam and 1/T_m.
_N_STILL = _STILL.stop - _STILL.start
AB_CURRENT = 0
AB_STILL = AB_CURRENT + 12 * _N_FEATURES
P_CURRENT = AB_STILL + 12 * _N_STILL
P_STILL = P_CURRENT + 6 * _N_FEATURES
EIGENVECTORS = P_STILL + 6 * _N_STILL
EIGENVALUES = EIGENVECTORS + 36
INV_T_M = EIGENVALUES + 6
#: ... and of the constants of :func:`rov_forces`: C_0^T (6 x features), dC^T (6 x morph features).
C0T, DCT = 0, 6 * _N_FEATURES
_N_MORPH = _MORPH.stop - _MORPH.start


@jit
def rov_features(x, u, d, F):
    """The feature vector F of one boat (module docstring), written to ``F`` in the order of the
    layout above. Returns whether a current is present and the Euler angles' sines and
    cosines."""
    sin = (np.sin(x[9]), np.sin(x[10]), np.sin(x[11]))
    cos = (np.cos(x[9]), np.cos(x[10]), np.cos(x[11]))
    current = d[0] != 0.0 or d[1] != 0.0 or d[2] != 0.0
    u_r, v_r, w_r = x[0], x[1], x[2]
    if current:  # the hydrodynamic terms act on the velocity through the water
        c_u, c_v, c_w = ned_to_body(sin, cos, d[0], d[1], d[2])
        u_r, v_r, w_r = u_r - c_u, v_r - c_v, w_r - c_w
    nur = local_array(6)  # (an array: a tuple indexed in a loop is copied at every index)
    nur[0], nur[1], nur[2], nur[3], nur[4], nur[5] = u_r, v_r, w_r, x[3], x[4], x[5]
    for i in range(3):
        for j in range(3):
            F[3 * i + j] = x[3 + i] * nur[j]
            F[_OMN.start + 3 * i + j] = x[3 + i] * x[j]
    F[_UV], F[_UW] = u_r * v_r, u_r * w_r
    for j in range(6):
        F[_TAU.start + j] = u[j]
        F[_ABS.start + j] = nur[j] * abs(nur[j])
    ang = _ANG.start
    for k in range(3):
        F[ang + k] = x[3 + k] * x[3 + k]
    F[ang + 3], F[ang + 4], F[ang + 5] = x[3] * x[4], x[3] * x[5], x[4] * x[5]
    F[_RES.start] = sin[1]  # sin(theta), cos(theta) sin(phi), cos(theta) cos(phi)
    F[_RES.start + 1] = cos[1] * sin[0]
    F[_RES.start + 2] = cos[1] * cos[0]
    return current, sin, cos


@jit
def rov_rhs(x, u, d, p, out):
    """One boat's ``x_dot`` (module docstring); ``p`` packed by :meth:`ROVModel.pack`."""
    F = local_array(_N_FEATURES)
    current, sin, cos = rov_features(x, u, d, F)
    first, width = (0, _N_FEATURES) if current else (_STILL.start, _N_STILL)
    s = x[12]
    if s != 0.0:  # nu_dot = V (A F + s B F[_MORPH]) / (1 + s lam)
        Y = local_array(12)
        _matvec(p, AB_CURRENT if current else AB_STILL, 12, width, F, first, Y)
        y = local_array(6)
        for i in range(6):
            y[i] = (Y[i] + Y[6 + i] * s) / (1.0 + p[EIGENVALUES + i] * s)
        _matvec(p, EIGENVECTORS, 6, 6, y, 0, out)
    else:  # cruise shape: M0^-1 is folded into one matrix
        _matvec(p, P_CURRENT if current else P_STILL, 6, width, F, first, out)
    # kinematics: NED velocity and Euler-angle rates
    out[6], out[7], out[8] = body_to_ned(sin, cos, x[0], x[1], x[2])
    out[9], out[10], out[11] = euler_rates(sin, cos, x[3], x[4], x[5])
    out[12] = (d[3] - s) * p[INV_T_M]


@jit
def rov_forces(x, u, d, p, out):
    """One boat's total generalised force ``-C_RB nu + tau_hyd + tau_s + tau`` (N, N m);
    ``p`` = :attr:`ROVModel.force_constants`."""
    F = local_array(_N_FEATURES)
    rov_features(x, u, d, F)
    morph = local_array(6)
    _matvec(p, C0T, 6, _N_FEATURES, F, 0, out)
    _matvec(p, DCT, 6, _N_MORPH, F, _MORPH.start, morph)
    for i in range(6):
        out[i] += x[12] * morph[i]


@jit
def rov_feature_row(x, u, d, p, out):
    """The feature vector of one boat (the identification's regressors)."""
    rov_features(x, u, d, out)


@jit
def _matvec(p, offset, n_rows, width, F, first, out):
    """``out[:n_rows] = P @ F[first:first + width]`` with ``P`` stored row by row from
    ``p[offset]``; each row summed in the order of the features, the rows side by side (their
    sums are independent: the processor runs them in parallel)."""
    for i in range(n_rows):
        out[i] = 0.0
    for j in range(width):
        f = F[first + j]
        for i in range(n_rows):
            out[i] += p[offset + i * width + j] * f


_FORCES = rows(rov_forces)
_FEATURES = rows(rov_feature_row)


class ROVModel(VehicleModel):
    """REMUS-100-type AUV/ROV with a cruise/work morphing hull (the morphing-robot patent;
    docs/models.md 3).

    :param params: the parameters; ``None`` = nominal (Prestero's REMUS-100 cruise shape and the
        [PROPOSED] work shape of docs/models.md 3.4).
    """

    name: ClassVar[str] = "rov"
    state_names: ClassVar[tuple[str, ...]] = (
        "u", "v", "w", "p", "q", "r", "x", "y", "z", "phi", "theta", "psi", "s")
    input_names: ClassVar[tuple[str, ...]] = ("X", "Y", "Z", "K", "M", "N")
    disturbance_names: ClassVar[tuple[str, ...]] = ("current_n", "current_e", "current_d", "s_cmd")
    state_units: ClassVar[tuple[str, ...]] = (
        "m/s", "m/s", "m/s", "rad/s", "rad/s", "rad/s", "m", "m", "m", "rad", "rad", "rad", "-")
    input_units: ClassVar[tuple[str, ...]] = ("N", "N", "N", "N m", "N m", "N m")
    disturbance_units: ClassVar[tuple[str, ...]] = ("m/s", "m/s", "m/s", "-")
    #: Nominal point: REMUS cruise speed, m/s, and depth, m.
    cruise_speed: ClassVar[float] = 1.5
    cruise_depth: ClassVar[float] = 5.0
    equations: ClassVar[Equations] = Equations(rov_rhs)

    def __init__(self, params: ROVParams | None = None) -> None:
        super().__init__(ROVParams() if params is None else params)
        k = self.params
        C0 = _coefficient_matrix(k, k.shape_at(0.0))
        dC = _coefficient_matrix(k, k.shape_at(1.0)) - C0
        if dC[:_MORPH.start].any():
            raise AssertionError("a morphing coefficient outside the morph features")
        still = C0[_STILL].copy()
        still[_OMN.start - _STILL.start:_OMN.stop - _STILL.start] += C0[_OMR]
        C0_cur = C0.copy()
        if k.current_inertia == "relative":
            # M_A nu_r_dot = M_A nu_dot + M_A [omega x nu_c; 0]: move the second term to the
            # right; omega_i nu_c_j = F[_OMN] - F[_OMR], so it is linear in the features
            term = _CROSS @ -added_mass(k)[:, :3].T
            C0_cur[_OMN] += term
            C0_cur[_OMR] -= term
        # tau_total = C0^T F + s dC^T F[_MORPH]   (forces(); trim)
        self._C0T, self._dCT = C0_cur.T.copy(), dC[_MORPH].T.copy()
        # M(s) = M0 + s dM = L^-1 diag(1 + s lam) V^-1, so M(s)^-1 = V diag(1 / (1 + s lam)) L
        M0 = mass_matrix(k, 0.0)
        dM = mass_matrix(k, 1.0) - M0
        if np.array_equal(M0, M0.T) and np.array_equal(dM, dM.T):
            from scipy.linalg import eigh  # (here, not at import: it takes 0.1 s)

            lam, V = eigh(dM, M0)  # V^T M0 V = I, V^T dM V = diag(lam)
            L = V.T
        else:  # non-symmetric added mass (Yrd != Nvd or Zqd != Mwd): general eigenproblem
            lam, V = np.linalg.eig(np.linalg.solve(M0, dM))
            require(bool(np.all(np.abs(lam.imag) < 1e-9 * (1 + np.abs(lam.real))))
                    and np.linalg.cond(V) < 1e8, "added mass (Yrd, Nvd, Zqd, Mwd)",
                    (k.Yrd, k.Nvd, k.Zqd, k.Mwd),
                    "too far from symmetric for the exact morph inverse")
            lam, V = lam.real, V.real
            L = np.linalg.solve(V, np.linalg.inv(M0))
        self._lam, self._V, self._L = lam, np.ascontiguousarray(V), np.ascontiguousarray(L)
        # nu_dot = V (A F + s B F[_MORPH]) / (1 + s lam); in cruise shape: nu_dot = P F
        A_cur, A_still = L @ C0_cur.T, L @ still.T
        AB_cur = np.zeros((12, _N_FEATURES))  # [A; B] over every feature (B zero outside)
        AB_cur[:6], AB_cur[6:, _MORPH] = A_cur, L @ dC[_MORPH].T
        AB_still = AB_cur[:, _STILL].copy()
        AB_still[:6] = A_still
        self._maps = (AB_cur, AB_still, V @ A_cur, V @ A_still)
        self._x0 = np.zeros(len(self.state_names))
        self._x0[[0, 8]] = self.cruise_speed, self.cruise_depth
        self._u0 = self.trim_forces(self.cruise_speed, 0.0)
        low, high = thruster_box()
        low[_K], high[_K] = -k.K_max, k.K_max
        self._u_bounds = (low, high)

    # -- nominal point, bounds, shape ---------------------------------------------------------
    @property
    def environment_disturbances(self) -> tuple[str, ...]:
        """The current (``s_cmd`` is the morph command, not the environment)."""
        return ("current_n", "current_e", "current_d")

    @property
    def x0(self) -> FloatArray:
        """Cruise at ``u = 1.5 m/s``, depth 5 m, level, heading north, cruise shape (s = 0)."""
        return self._x0.copy()

    @property
    def u0(self) -> FloatArray:
        """Generalised forces holding :attr:`x0` at zero acceleration (``x`` still grows at
        1.5 m/s): surge thrust against the drag, heave force against the net buoyancy."""
        return self._u0.copy()

    @property
    def u_bounds(self) -> tuple[FloatArray, FloatArray]:
        """Box of the thruster layout's reachable range per row (X [-40, 60] N, Y and Z +-20 N,
        M +-18.75 N m, N +-13.5 N m) and the idealised roll moment +-K_max."""
        return self._u_bounds[0].copy(), self._u_bounds[1].copy()

    def coefficients(self, s: float) -> dict[str, float]:
        """Interpolated coefficients, r_G, r_B (m) and I_b (kg m^2) at morph fraction ``s``
        (:meth:`ROVParams.shape_at`)."""
        return self.params.shape_at(s)

    def mass_matrix(self, s: float = 0.0) -> FloatArray:
        """``M_RB(s) + M_A`` (6x6) at morph fraction ``s``."""
        return mass_matrix(self.params, s)

    def trim_forces(self, u_speed: float, s: float = 0.0) -> FloatArray:
        """Generalised forces (N, N m) that hold steady, level, straight motion at surge speed
        ``u_speed`` (m/s) in still water with the hull held at shape ``s`` (``s_cmd = s``):
        ``X = -Xuu(s) u|u|``, ``Z = -(W - B)``, ``M = x_G W - x_B B`` (interpolated)."""
        x = np.zeros(len(self.state_names))
        x[[0, 8, 12]] = u_speed, self.cruise_depth, s
        return 0.0 - self.forces(x, np.zeros(6), np.array([0.0, 0.0, 0.0, s]))  # no -0.0

    # -- dynamics ------------------------------------------------------------------------------
    def pack(self) -> FloatArray:
        """The constants of :func:`rov_rhs`: the maps of the module docstring, V, lam, 1/T_m."""
        return np.concatenate([*(a.ravel() for a in self._maps), self._V.ravel(), self._lam,
                               [1.0 / self.params.T_m]])

    @functools.cached_property
    def force_constants(self) -> FloatArray:
        """The constants of :func:`rov_forces`: C_0^T and dC^T row by row."""
        return np.concatenate([self._C0T.ravel(), self._dCT.ravel()])

    def forces(self, x: ArrayLike, u: ArrayLike, d: ArrayLike | None = None) -> FloatArray:
        """Total generalised force at the CB, ``-C_RB nu + tau_hyd + tau_s + tau`` (N, N m),
        shape ``(..., 6)``: the right-hand side of ``M(s) nu_dot = ...``."""
        x, u, d = self._split(x, u, d)
        return evaluate(_FORCES, x, u, d, self.force_constants, width=6)

    def features(self, x: ArrayLike, d: ArrayLike | None = None) -> FloatArray:
        """The feature vector F of the module docstring (products of the water-relative motion,
        the inputs, the restoring terms), shape ``(..., 41)``, of states ``(..., 13)`` with
        disturbances ``d`` (None = still water, no morph command)."""
        x, u, d = self._split(x, np.zeros(6), d)
        return evaluate(_FEATURES, x, u, d, np.zeros(1), width=_N_FEATURES)

    def hydrodynamic_regressors(self, x: ArrayLike, names: Sequence[str],
                                d: ArrayLike | None = None) -> FloatArray:
        """``d tau_hyd / d theta``: the feature of each coefficient (e.g. ``u_r|u_r|`` for ``Xuu``,
        on the velocity through the water) in its force row, zero elsewhere. ``tau_hyd`` is linear
        in the coefficients, so this is exact: ``tau_hyd = regressors @ theta``.

        :param x: states, shape ``(..., 13)``.
        :param names: coefficients, each one of :data:`HYDRO_COEFFICIENTS` (``p`` of them).
        :param d: disturbances (current, m/s; morph command), shape ``(..., 4)``; None = zero.
        :return: shape ``(..., 6, p)``; force rows N or N m per coefficient unit.
        """
        rows_of, select = _hydro_layout(tuple(names))
        terms = self.features(x, d)[..., rows_of]
        return terms[..., None, :] * select.T

    def rhs_with(self, x: ArrayLike, u: ArrayLike, d: ArrayLike | None,
                 params: Mapping[str, ArrayLike]) -> FloatArray:
        """:meth:`rhs` with parameters replaced per batch row.

        A hydrodynamic coefficient (one of :data:`HYDRO_COEFFICIENTS`) gives its value AT THE
        CURRENT SHAPE ``s``: it replaces the interpolated ``c(s)``, so that an identifier
        estimates what the hull has now. ``tau_hyd`` is linear in the coefficients and ``tau``
        enters beside it, so this is exactly ``rhs(x, u + Phi (theta - c(s)), d)`` =
        ``rhs + [M(s)^-1 Phi (theta - c(s)); 0]`` with ``Phi`` = :meth:`hydrodynamic_regressors`:
        the model's exact ``M(s)^-1`` at the cost of one ``rhs``. Other names (``m``,
        ``work_Xuu``, ...) go to the generic path of :meth:`VehicleModel.rhs_with`; mixed with
        coefficients, each coefficient is passed there as its cruise AND work value (same
        meaning, slower).

        :param x, u, d: as :meth:`rhs`.
        :param params: ``{name: value}``, each a scalar or an array broadcasting with the batch
            shape (e.g. ``(N,)`` for ``x`` of shape ``(N, 13)``), in the parameter's unit.
        :return: ``x_dot``, shape ``(..., 13)`` over the broadcast batch shape.
        """
        hydro = {k: v for k, v in params.items() if k in _HYDRO_ENTRIES}
        if not hydro:
            return super().rhs_with(x, u, d, params)
        if len(hydro) < len(params):
            other = {k: v for k, v in params.items() if k not in _HYDRO_ENTRIES}
            return super().rhs_with(x, u, d, _shape_free(hydro, other))
        x, u, d, theta, shape = self._batch_with(x, u, d, list(hydro.values()))
        rows_of, select = _hydro_layout(tuple(hydro))
        cruise, change = self._morph_line(tuple(hydro))
        terms = self.features(x, d)[:, rows_of]
        terms *= theta - (cruise + x[:, 12:13] * change)
        return self.rhs(x, u + terms @ select, d).reshape(*shape, 13)

    def parameter_jacobian(self, x: ArrayLike, u: ArrayLike, d: ArrayLike | None,
                           params: Mapping[str, ArrayLike]) -> FloatArray | None:
        """``d rhs_with / d params``, shape ``(..., 13, p)`` in the order of ``params``: exact
        ``[M(s)^-1 Phi; 0]`` when every name is a hydrodynamic coefficient (``rhs_with`` is
        linear in them, so the values themselves do not matter), else the base class's answer.
        """
        if not params or not set(params) <= _HYDRO_ENTRIES.keys():
            return super().parameter_jacobian(x, u, d, params)
        x, _, d, _, shape = self._batch_with(x, u, d, list(params.values()))
        rows_of, select = _hydro_layout(tuple(params))
        phi = self.features(x, d)[:, None, rows_of] * select.T[None]  # (n, 6, p)
        # M(s)^-1 = V diag(1 / (1 + s lam)) L, exact for every s
        scaled = (self._L @ phi) / (1.0 + x[:, 12, None, None] * self._lam[:, None])
        out = np.zeros((x.shape[0], 13, len(rows_of)))
        out[:, :6] = self._V @ scaled
        return out.reshape(*shape, 13, len(rows_of))

    def compiled_parameters(self, names: tuple[str, ...]) -> CompiledParameters | None:
        """Hydrodynamic coefficients (:data:`HYDRO_COEFFICIENTS`, at the current shape as
        :meth:`rhs_with` means them): packed constants affine in them and their exact Jacobian
        (:mod:`marine_envs.models.rov_coefficients`); None for any other name."""
        if not set(names) <= set(HYDRO_COEFFICIENTS):
            return None
        return coefficient_parameters(self, tuple(names), rov_features, MORPHING)

    def _batch_with(self, x: ArrayLike, u: ArrayLike, d: ArrayLike | None,
                    values: list[ArrayLike]):
        """Flat ``x, u, d`` and the parameter matrix ``theta`` (n, p) over the broadcast batch
        shape of the arrays and the parameter values, and that shape."""
        x, u, d = self._split(x, u, d)
        arrays = [np.asarray(v, dtype=float) for v in values]
        shape = np.broadcast_shapes(x.shape[:-1], u.shape[:-1], d.shape[:-1],
                                    *(a.shape for a in arrays))
        size = math.prod(shape)
        x, u, d = (a.reshape(-1, a.shape[-1]) if a.shape[:-1] == shape else
                   np.broadcast_to(a, (*shape, a.shape[-1])).reshape(-1, a.shape[-1])
                   for a in (x, u, d))
        theta = np.empty((size, len(arrays)))
        for j, a in enumerate(arrays):
            theta[:, j] = a.reshape(-1) if a.shape == shape else np.broadcast_to(a, shape).ravel()
        return x, u, d, theta, shape

    def _morph_line(self, names: tuple[str, ...]) -> tuple[FloatArray, FloatArray]:
        """Cruise values and work-minus-cruise changes of ``names``: ``c(s) = c_0 + s dc``."""
        k = self.params
        cruise = np.array([getattr(k, n) for n in names])
        change = np.array([getattr(k, f"work_{n}") - getattr(k, n) if n in MORPHING else 0.0
                           for n in names])
        return cruise, change


__all__ = ["HYDRO_COEFFICIENTS", "MORPHING", "SEED_COEFFICIENTS", "THRUSTER_ALLOCATION",
           "THRUSTER_DIRECTIONS", "THRUSTER_LIMITS", "THRUSTER_POSITIONS", "ROVModel",
           "ROVParams", "added_mass", "allocate", "mass_matrix"]
