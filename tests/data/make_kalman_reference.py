"""Writes ``kalman_reference.npz``: the Kalman and adaptive Kalman filters of
``tests/test_kalman.py``'s exactness scenarios run by the numpy update of commit b31a8e0 (the
batched numpy code the compiled kernels replaced, ``KalmanFilter.run_in_numpy``), so that the
kernels are tested against recorded numbers instead of a second implementation.

Made with the code of commit b31a8e0 (``PYTHONPATH=<that checkout> python
tests/data/make_kalman_reference.py``, run from this checkout: the scenarios are the test's).
"""

import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
from test_kalman import SCENARIOS, run_scenario  # noqa: E402


def main() -> None:
    arrays = {}
    for name, case in SCENARIOS.items():
        for key, value in run_scenario(case, reference=True).items():
            arrays[f"{name}/{key}"] = value
    np.savez_compressed(HERE / "kalman_reference.npz", **arrays)


if __name__ == "__main__":
    main()
