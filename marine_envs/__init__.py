"""marine-envs: Gymnasium environments for marine vehicles.

Importing the package registers the environments::

    import gymnasium as gym
    import marine_envs  # noqa: F401
    env = gym.make("marine_envs/USV-v0")

The environment classes are exported here too (``marine_envs.USVEnv``, ``USVVectorEnv``, ...).
"""

from gymnasium.envs.registration import register

from .envs import (
    DPVesselEnv,
    DPVesselVectorEnv,
    HovercraftEnv,
    HovercraftVectorEnv,
    HydrofoilEnv,
    HydrofoilVectorEnv,
    MarineEnv,
    MarineVectorEnv,
    ROVEnv,
    ROVVectorEnv,
    USVEnv,
    USVVectorEnv,
)

__version__ = "0.1.0"

#: Registered environment ids -> (module in marine_envs.envs, class name prefix, episode steps).
ENVIRONMENTS = {
    "marine_envs/USV-v0": ("usv", "USV", 1000),
    "marine_envs/Hydrofoil-v0": ("hydrofoil", "Hydrofoil", 12000),
    "marine_envs/ROV-v0": ("rov", "ROV", 1000),
    "marine_envs/DPVessel-v0": ("dp_vessel", "DPVessel", 1000),
    "marine_envs/Hovercraft-v0": ("hovercraft", "Hovercraft", 1000),
}

for _id, (_module, _prefix, _steps) in ENVIRONMENTS.items():
    register(id=_id, entry_point=f"marine_envs.envs.{_module}:{_prefix}Env",
             vector_entry_point=f"marine_envs.envs.{_module}:{_prefix}VectorEnv",
             max_episode_steps=_steps)

__all__ = ["ENVIRONMENTS", "DPVesselEnv", "DPVesselVectorEnv", "HovercraftEnv",
           "HovercraftVectorEnv", "HydrofoilEnv", "HydrofoilVectorEnv", "MarineEnv",
           "MarineVectorEnv", "ROVEnv", "ROVVectorEnv", "USVEnv", "USVVectorEnv"]
