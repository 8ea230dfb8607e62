"""Writes ``effects_reference.npz``: the catalogue's state terms, input effects and environments
with effects as the numpy implementations the compiled terms replaced computed them.

Made with the code of commit b31a8e0 (``PYTHONPATH=<that checkout> python
tests/data/make_effects_reference.py``), where a model with state effects was
``ModelWithEffects`` (numpy terms after the compiled equations), input effects ran in
``ActuatorStream`` / ``BatchActuators`` (Python, sample by sample) and an environment with
effects stepped in numpy. The effects are stored with the results (as JSON), so that the test
rebuilds exactly what was run.
"""

import json
from pathlib import Path

import gymnasium as gym
import numpy as np

import marine_envs  # noqa: F401 - registers the environments
from marine_envs.models import get_model
from marine_envs.models.effects import ActuatorStream, BatchActuators, Effect

#: Each model's time-invariant state terms, one of each kind (names as in the model).
STATE_TERMS = {
    "usv": [("current", "r", {"b": 0.01}), ("linear_damping", "v", {"c": -0.2}),
            ("quadratic_damping", "p", {"c": -1.0}),
            ("coupling", "r", {"source": "phi", "c": 0.05}),
            ("nonlinear_damping", "p", {"c": -3.0}),
            ("nonlinear_restoring", "p", {"source": "phi", "c": -0.5}),
            ("unlisted", "r", {"expression": "v*delta*phi", "c": 0.4})],
    "hovercraft": [("current", "v", {"b": 0.02}), ("quadratic_damping", "r", {"c": -0.8}),
                   ("coupling", "v", {"source": "r", "c": 0.1}),
                   ("unlisted", "u", {"expression": "sigma_1*u", "c": -0.05})],
    "rov": [("quadratic_damping", "w", {"c": -0.3}), ("nonlinear_damping", "r", {"c": -0.2}),
            ("coupling", "q", {"source": "theta", "c": -0.1})],
}
#: Input effects, alone and chained.
INPUT_EFFECTS = [("input_gain", "delta", {"k": 0.7}), ("input_delay", "delta", {"tau": 0.33}),
                 ("input_delay", "delta", {"tau": 0.3}),
                 ("input_saturation", "delta", {"limit": 0.1}),
                 ("input_deadzone", "delta", {"width": 0.05}),
                 ("input_rate_limit", "delta", {"rate": 0.2})]
#: Environments with state, input and sensor-bias effects (waves on, noisy sensors).
ENVS = {
    "usv": ("marine_envs/USV-v0", [
        ("quadratic_damping", "p", {"c": -1.0}), ("coupling", "r", {"source": "phi", "c": 0.05}),
        ("input_delay", "delta", {"tau": 0.25}), ("input_rate_limit", "delta", {"rate": 0.3}),
        ("sensor_bias", "phi", {"b": 0.01})], {"max_roll": 0.3}),
    "hovercraft": ("marine_envs/Hovercraft-v0", [
        ("quadratic_damping", "r", {"c": -0.8}), ("input_saturation", "sigma_1", {"limit": 0.1}),
        ("input_rate_limit", "delta", {"rate": 0.1}), ("input_gain", "sigma_2", {"k": 0.8}),
        ("sensor_bias", "psi", {"b": -0.02})], {}),
}
STEPS = 300


def effects(entries):
    return [Effect(name, target, parameters) for name, target, parameters in entries]


def batch_rows(batch: BatchActuators, commanded: np.ndarray) -> np.ndarray:
    """Two boats' applied inputs for ``commanded`` and minus half of it; boat 1 reset at
    sample 100."""
    batch.bind(2)
    rows = []
    for j, c in enumerate(commanded):
        if j == 100:
            batch.reset([1])
        rows.append(batch.step(np.stack([c, -0.5 * c])))
    return np.array(rows)


def main() -> None:
    from marine_envs.models.effects import ModelWithEffects  # (b31a8e0's)

    out, rng = {}, np.random.default_rng(2024)
    for name, entries in STATE_TERMS.items():
        model = get_model(name)
        n = 40
        x = rng.normal(size=(n, len(model.state_names)))
        u = rng.normal(size=(n, len(model.input_names)))
        d = rng.normal(size=(n, len(model.disturbance_names)))
        out |= {f"terms/{name}/x": x, f"terms/{name}/u": u, f"terms/{name}/d": d,
                f"terms/{name}/rhs": ModelWithEffects(model, effects(entries)).rhs(x, u, d)}
        for k, entry in enumerate(entries):
            out[f"terms/{name}/{k}"] = ModelWithEffects(model, effects([entry])).rhs(x, u, d)
    usv = get_model("usv")
    chains = [[e] for e in INPUT_EFFECTS] + [INPUT_EFFECTS, INPUT_EFFECTS[::-1]]
    for dt in (0.1, 0.05):
        commanded = rng.normal(size=(150, 1)) * 0.3
        commanded[60:70] = 0.0
        out[f"inputs/{dt}/commanded"] = commanded
        for k, chain in enumerate(chains):
            stream = ActuatorStream(usv, effects(chain), dt)
            out[f"inputs/{dt}/stream/{k}"] = np.array([stream.step(c) for c in commanded])
            out[f"inputs/{dt}/batch/{k}"] = batch_rows(BatchActuators(usv, effects(chain), dt),
                                                       commanded)
    for key, (env_id, entries, kwargs) in ENVS.items():
        env = gym.make(env_id, effects=effects(entries), **kwargs)
        obs, _ = env.reset(seed=7)
        actions = np.random.default_rng(5).uniform(-1.3, 1.3, (STEPS, *env.action_space.shape))
        rows = {k: [] for k in ("obs", "reward", "state", "applied", "commanded", "ended")}
        for action in actions:
            obs, reward, term, trunc, info = env.step(action)
            for k, v in (("obs", obs), ("reward", reward), ("state", info["state"]),
                         ("applied", info["action_applied"]),
                         ("commanded", info["action_commanded"]), ("ended", term or trunc)):
                rows[k].append(np.array(v, copy=True))
            if term or trunc:
                obs, _ = env.reset()
        out |= {f"env/{key}/actions": actions} | {f"env/{key}/{k}": np.array(v)
                                                  for k, v in rows.items()}
    spec = {"state_terms": STATE_TERMS, "input_effects": INPUT_EFFECTS, "chains": chains,
            "envs": ENVS, "steps": STEPS}
    np.savez_compressed(Path(__file__).with_name("effects_reference.npz"),
                        spec=json.dumps(spec), **out)


if __name__ == "__main__":
    main()
