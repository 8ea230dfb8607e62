"""A trial vessel for the guide "Putting the diagnosed vessel back into the environment": a USV
that is not quite the nominal model, and its free roll decay recorded through the environment's
own sensors (read this file after the guide: the guide's diagnosis is to find out what it is).
"""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pandas as pd

import marine_envs  # noqa: F401  (registers the environments)
from marine_envs.models.effects import Effect
from marine_envs.recording import Recording

ENV_ID = "marine_envs/USV-v0"
#: The vessel as it is: environment arguments that the nominal USV does not have.
VESSEL = {"params": {"zeta": 0.02},
          "effects": [Effect("quadratic_damping", "p", {"c": -1.0})]}


def roll_decay(heel_deg: float = 20.0, seconds: float = 120.0, seed: int = 1) -> Recording:
    """A free roll decay in calm water from ``heel_deg``, rudder amidships, the roll rate and
    angle as the vessel's gyro and inclinometer give them (the environment's default sensors)."""
    # without Gymnasium's passive checker: with effects, the environment hands out one
    # read-only all-valid measurement mask at every step, which the checker flags
    env = gym.make(ENV_ID, waves=False, disable_env_checker=True, **VESSEL)
    x0 = np.zeros(5)
    x0[4] = math.radians(heel_deg)
    obs, info = env.reset(seed=seed, options={"state": x0})
    channels = env.unwrapped.system.channels
    rows = []
    for k in range(int(round(seconds / env.unwrapped.dt))):
        rows.append((k * env.unwrapped.dt, 0.0, obs[channels.index("p")],
                     obs[channels.index("phi")]))
        obs, *_ = env.step(np.zeros(1))
    data = pd.DataFrame(rows, columns=["time", "delta", "p", "phi"])
    return Recording(data, model="usv", meta={"test": f"roll decay from {heel_deg:g} deg"})
