"""Writes ``ekf_rov_reference.npz``: the benchmark's joint ROV EKF (benchmarks/ekf_throughput.py)
run by the numpy EKF the compiled one replaced, on a closed-loop record through the morph.

Made with the code of commit 97dcd08 (``PYTHONPATH=<that checkout> python
tests/data/make_ekf_rov_reference.py``): the record (forces, outputs, morph command, the noisy
measurements) is stored with the estimates, so that the test replays exactly what was filtered.
"""

import sys
from pathlib import Path

import numpy as np

import estimators

ROOT = Path(estimators.__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
import ekf_throughput as bench  # noqa: E402

STEPS, FILTERS, EVERY = 200, 3, 10


def main() -> None:
    forces, outputs, s_cmd = bench.closed_loop_record(STEPS)
    y = bench.noisy(outputs, FILTERS, seed=11)
    ekf = bench.make_filter(FILTERS)
    x, std = [], []
    for k in range(STEPS):
        ekf.disturbance[:, 3] = s_cmd[k]
        ekf.update(y[k])
        ekf.predict(forces[k])
        if k % EVERY == EVERY - 1:
            x.append(ekf.x.copy())
            std.append(np.sqrt(np.diagonal(ekf.P, axis1=1, axis2=2)))
    np.savez_compressed(Path(__file__).with_name("ekf_rov_reference.npz"), forces=forces,
                        s_cmd=s_cmd, y=y, x=np.array(x), std=np.array(std), P=ekf.P,
                        every=EVERY, diverged=ekf.diverged)


if __name__ == "__main__":
    main()
