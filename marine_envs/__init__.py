"""marine-envs: Gymnasium environments for marine vehicles.

Importing the package registers the environments::

    import gymnasium as gym
    import marine_envs  # noqa: F401
    env = gym.make("marine_envs/USV-v0")
"""

from gymnasium.envs.registration import register

__version__ = "0.1.0"

#: Registered environment ids -> (module of the environment, class name prefix).
ENVIRONMENTS = {
    "marine_envs/USV-v0": ("usv", "USV"),
    "marine_envs/Hydrofoil-v0": ("hydrofoil", "Hydrofoil"),
    "marine_envs/ROV-v0": ("rov", "ROV"),
    "marine_envs/DPVessel-v0": ("dp_vessel", "DPVessel"),
    "marine_envs/Hovercraft-v0": ("hovercraft", "Hovercraft"),
}

for _id, (_module, _prefix) in ENVIRONMENTS.items():
    register(id=_id, entry_point=f"marine_envs.envs.{_module}:{_prefix}Env",
             vector_entry_point=f"marine_envs.envs.{_module}:{_prefix}VectorEnv",
             max_episode_steps=1000)
