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


_COUPLINGS = {"usv": USVWaveCoupling}


def wave_coupling(model: VehicleModel, heading: float, **options: float) -> Coupling:
    """The coupling of ``model`` (by its name) at encounter angle ``heading`` (rad)."""
    try:
        cls = _COUPLINGS[model.name]
    except KeyError:
        raise ValueError(f"no wave coupling defined for model {model.name!r}") from None
    coupling = cls(heading=heading, **options)
    return lambda omega: coupling(omega, model)
