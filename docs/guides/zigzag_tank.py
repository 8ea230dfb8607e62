"""A model basin for the zigzag guide: seeded zigzag tests of a ship whose yaw has one term the
Nomoto model leaves out (read this file after the guide, not before: the guide's diagnosis is
to find it).

The ship is Nomoto's first-order yaw model with its own K and T plus a catalogue effect, steered
by the ITTC zigzag law of :func:`marine_envs.manoeuvres.zigzag` with a rudder rate of 15 deg/s.
The gyro and the compass add white noise; the recorded rudder is the actual rudder angle.
"""

from __future__ import annotations

import math

import numpy as np

from marine_envs.manoeuvres import zigzag
from marine_envs.models import get_model
from marine_envs.models.effects import Effect, EffectModel
from marine_envs.recording import Recording

#: The ship's own Nomoto parameters (the model's defaults are K = -0.08 1/s, T = 10 s).
SHIP = {"K": -0.1, "T": 8.0}
#: What the Nomoto model leaves out: a cubic (Norrbin) yaw damping, rad/s^2 per (rad/s)^3.
HIDDEN = Effect("nonlinear_damping", "r", {"c": -20.0, "form": "cubic"})
RUDDER_RATE = math.radians(15.0)  # rad/s
NOISE = {"r": math.radians(0.02), "psi": math.radians(0.05)}  # gyro rad/s, compass rad
DT, DURATION = 0.2, 80.0  # s: a 5 Hz log of 80 s per test


def zigzag_test(amplitude_deg: float, seed: int) -> Recording:
    """The ``amplitude_deg``/``amplitude_deg`` zigzag test (starboard first), as recorded."""
    ship = EffectModel(get_model("nomoto", **SHIP), [HIDDEN])
    a = math.radians(amplitude_deg)
    # K < 0: a positive (port) rudder turns the heading negative, hence turn_sign=-1
    run = zigzag(ship, a, a, duration=DURATION, dt=DT, turn_sign=-1, rudder_rate=RUDDER_RATE)
    rng = np.random.default_rng(seed)
    measured = {name: run.states[:, i] + NOISE[name] * rng.standard_normal(len(run.time))
                for i, name in enumerate(ship.state_names)}
    return Recording.from_arrays("nomoto", run.time, run.rudder, measured,
                                 meta={"test": f"zigzag {amplitude_deg:g}/{amplitude_deg:g}"})
