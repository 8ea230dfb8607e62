"""From the sea to each model's disturbance inputs.

A coupling is a function of the wave frequency returning, for each disturbance input of a model,
the complex amplitude per metre of wave amplitude (a first-order response amplitude operator).
:class:`~marine_envs.sea.waves.WaveRealisation` sums it over the wave components.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from numpy.typing import NDArray

from ..models import VehicleModel
from .waves import Coupling, G


@dataclasses.dataclass(frozen=True)
class USVWaveCoupling:
    """Wave yaw and roll moments (per unit inertia) on the USV, from the wave slope.

    Roll **[RECALLED, Froude-Krylov for a ship short against the wave]**: the waves tilt the
    hydrostatic restoring moment, ``-wn^2 phi`` becomes ``-wn^2 (phi - alpha)``, so
    ``w_phi = wn^2 * alpha`` with ``alpha`` the transverse wave slope ``k a sin(beta)``.
    Yaw **[PROPOSED]**: the wave yaw moment of a slender hull goes as ``k a sin(2 beta)``; it is
    expressed as an equivalent rudder angle ``yaw_gain * k a sin(2 beta)`` through the model's
    rudder-to-yaw-acceleration gain ``Kdr/Tr``, so the ship's own rudder authority sets its scale.
    Both decay as ``exp(-k draft)`` (Smith effect: pressure falls off with depth), which removes
    the short waves a hull does not feel. Following the slope, both lag the elevation by 90 deg.

    :param heading: encounter angle beta, rad (pi = head seas, pi/2 = beam seas).
    :param roll_gain: effective-slope coefficient, - (1 = full wave slope).
    :param yaw_gain: equivalent rudder angle per rad of wave slope, rad/rad.
    :param draft: effective draft for the Smith factor, m.
    """

    heading: float
    roll_gain: float = 1.0
    yaw_gain: float = 10.0
    draft: float = 3.0

    def __call__(self, omega: NDArray[np.float64], model: VehicleModel) -> NDArray[np.complex128]:
        k = omega**2 / G
        slope = -1j * k * np.exp(-k * self.draft)
        params = model.params
        w_psi = abs(params.Kdr / params.Tr) * self.yaw_gain * math.sin(2 * self.heading) * slope
        w_phi = params.wn**2 * self.roll_gain * math.sin(self.heading) * slope
        return np.stack([w_psi, w_phi], axis=1)


@dataclasses.dataclass(frozen=True)
class HydrofoilWaveCoupling:
    """Orbital velocities and surface elevation at the hydrofoil's two foils (docs/models.md 2.5).

    Deep-water linear waves **[RECALLED, standard]**, wave number ``k = omega^2/g``, foil i at
    ``x_i`` along the hull (``x_1 = +l1`` front, ``x_2 = -l2`` rear, m) and at its trim depth
    ``hbar_i`` (m, taken from the model's trim). Per metre of wave amplitude, with the phase
    ``phi_i = omega_e t - k x_i cos(beta) + eps``::

        eta_i      = cos(phi_i)                                      H = exp(-i k x_i cos b)
        zeta_dot_i = -omega exp(-k hbar_i) sin(phi_i)                H = i omega exp(-k hbar_i) ...
        u_w,i      = cos(b) omega exp(-k hbar_i) cos(phi_i)          H = cos(b) omega exp(...) ...

    ``zeta_dot`` (upward, m/s) and ``u_w`` (along +x, m/s) are the particle velocities at a fixed
    earth point, so their amplitude uses the wave frequency omega while the phase runs at the
    encounter frequency. The decay uses the fixed trim depth, not the instantaneous one.
    ``k`` uses the sea's gravity (9.81 m/s^2, as the realisation's encounter frequency does),
    not the hydrofoil AKF paper's 9.80: the waves belong to the sea, not to the craft.

    :param heading: encounter angle beta, rad (Fossen: pi = head seas, 0 = following seas).
    :param rich: False (the paper's model, docs/models.md 2.4): only the ``zeta_dot`` channels,
        the ``eta`` and ``u_w`` columns are zero. True: all six channels (the "richer truth
        model").
    """

    heading: float
    rich: bool = False

    def __call__(self, omega: NDArray[np.float64], model: VehicleModel) -> NDArray[np.complex128]:
        omega = np.asarray(omega, dtype=float)[:, None]
        k = omega**2 / G
        x = model.params.foil_x[None, :]  # [+l1, -l2], m
        hbar = model.trim.h[None, :]  # trim submergence of each foil, m
        cos_beta = math.cos(self.heading)
        travel = np.exp(-1j * k * x * cos_beta)  # phase lag of the wave between the foils
        orbital = omega * np.exp(-k * hbar) * travel  # orbital speed at depth, m/s per m
        out = np.zeros((omega.shape[0], 6), dtype=complex)
        out[:, 0:2] = 1j * orbital
        if self.rich:
            out[:, 2:4] = travel
            out[:, 4:6] = cos_beta * orbital
        return out


_COUPLINGS = {"usv": USVWaveCoupling, "hydrofoil": HydrofoilWaveCoupling}


def wave_coupling(model: VehicleModel, heading: float, **options: float) -> Coupling:
    """The coupling of ``model`` (by its name) at encounter angle ``heading`` (rad)."""
    try:
        cls = _COUPLINGS[model.name]
    except KeyError:
        raise ValueError(f"no wave coupling defined for model {model.name!r}") from None
    coupling = cls(heading=heading, **options)
    return lambda omega: coupling(omega, model)
