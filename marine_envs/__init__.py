"""marine-envs: Gymnasium environments for marine vehicles.

Importing the package registers the environments::

    import gymnasium as gym
    import marine_envs  # noqa: F401
    env = gym.make("marine_envs/USV-v0")
"""

from gymnasium.envs.registration import register

__version__ = "0.1.0"

#: Registered environment ids, with their single and vector entry points.
ENVIRONMENTS = {
    "marine_envs/USV-v0": ("marine_envs.envs.usv:USVEnv", "marine_envs.envs.usv:USVVectorEnv"),
}

for _id, (_entry, _vector_entry) in ENVIRONMENTS.items():
    register(id=_id, entry_point=_entry, vector_entry_point=_vector_entry,
             max_episode_steps=1000)
