"""Writes ``sensor_reference.npz``: sensor chains measured stage by stage by the numpy stages
the compiled chain replaced (each stage's own numpy arithmetic).

Made with the code of commit b31a8e0 (``PYTHONPATH=<that checkout> python
tests/data/make_sensor_reference.py``): the chains are the standard ones of ``CHAINS`` and a
zooming quantizer on the "zoom" law, 4 boats, true values from a seeded generator, two boats
restarted midway; the measurements and their valid channels are stored.
"""

import json
import math
from pathlib import Path

import numpy as np

from marine_envs.sensors import GaussianNoise, Saturation, SensorSuite, ZoomingQuantizer

CHANNELS = ("a", "b", "c")
CHAINS = [dict(noise_std=0.1),
          dict(noise_std={"a": 0.1}, quantization=0.05, wrap=("b",), sensor_range=2.0),
          dict(bias=0.3, noise_std=0.2, sample_period={"a": 3, "c": 2}, delay={"b": 2, "c": 5},
               dropout=0.3),
          dict(noise_std=0.05, quantization={"a": 0.1, "c": 0.2}, quantizer="zooming"),
          dict(dropout={"a": 0.5}, delay=1, sensor_range={"c": 1.0}),
          dict(bias={"b": -0.2}, quantization={"c": 0.3}, wrap=("a", "c")), {}]
BOATS, STEPS = 4, 300


def zoom_law_suite() -> SensorSuite:
    return SensorSuite(CHANNELS, [
        GaussianNoise([0.1, 0.1, 0.1]),
        ZoomingQuantizer([[0, 2], [1]], law="zoom", levels=4, mu0=0.5), Saturation([3, 3, 3])])


def true_values(k: int, rng: np.random.Generator) -> np.ndarray:
    """Step ``k``'s true values: large and small by turns, one of them past the wrap."""
    z = rng.normal(size=(BOATS, 3)) * (3 if k % 50 < 25 else 0.1)
    z[k % BOATS, k % 3] = math.pi + 0.5 * (k % 2)
    return z


def run(suite: SensorSuite) -> tuple[np.ndarray, np.ndarray]:
    """Measurements and valid channels over the schedule."""
    suite.bind(BOATS)
    suite.reset(np.arange(BOATS), [np.random.default_rng(i) for i in range(BOATS)])
    rng = np.random.default_rng(99)
    y_all, valid_all = [], []
    for k in range(STEPS):
        z = true_values(k, rng)
        if k % 97 == 50:  # boats restarting midway
            suite.reset(np.array([1, 3]), [np.random.default_rng(1000 + k + i) for i in range(2)])
        y_all.append(suite.measure(z.copy()))
        valid_all.append(np.broadcast_to(suite.valid, z.shape).copy())
    return np.array(y_all), np.array(valid_all)


def main() -> None:
    out = {}
    for k, make in enumerate([lambda kw=kw: SensorSuite.standard(CHANNELS, **kw)
                              for kw in CHAINS] + [zoom_law_suite]):
        out[f"{k}/y"], out[f"{k}/valid"] = run(make())
    np.savez_compressed(Path(__file__).with_name("sensor_reference.npz"),
                        chains=json.dumps(CHAINS), **out)


if __name__ == "__main__":
    main()
