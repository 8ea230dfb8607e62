"""benchmarks/real_recordings.py, the parts that need no ../shared data: the HSVA zigzag reader
(units, signs, heading relative and unwrapped) and the plain LS fit of a linear decay."""

import math

import numpy as np
import pytest
from benchmark_module import load_benchmark

bench = load_benchmark("real_recordings")


def test_zigzag_reader_and_linear_decay_fit(tmp_path):
    # a tiny HSVA file: 4 latin-1 header lines, 12 columns at 20 Hz, heading crossing +-180 deg
    t = 3.0 + 0.05 * np.arange(6)
    psi_deg = [179.0, 179.5, -180.0, -179.5, -179.0, -178.5]  # +0.5 deg per sample
    rows = [[tk, 1.0 + k, 0.1, psi_deg[k], 1.18, 0.0, 10.0, 0.2, 5.0, 10.23, 41.0, 1.0]
            for k, tk in enumerate(t)]
    path = tmp_path / "Z_test.dat"
    path.write_bytes((" HSVA\n KVLCC2\n Z10\xb0/10\xb0\n Time series\n").encode("latin-1")
                     + "\n".join(" ".join(f"{v:.9f}" for v in row) for row in rows).encode())
    rec = bench.read_hsva_zigzag(path)
    assert rec.model == "nomoto" and rec.measured_names == ("r", "psi")
    np.testing.assert_allclose(rec.time, 0.05 * np.arange(6), atol=1e-12)
    np.testing.assert_allclose(rec.inputs[:, 0], math.radians(5.0))  # deg -> rad, sign kept
    np.testing.assert_allclose(rec.data["r"], math.radians(10.0))  # deg/s -> rad/s
    np.testing.assert_allclose(rec.data["psi"], np.radians(0.5 * np.arange(6)), atol=1e-12)

    # the plain least-squares fit recovers a linear decay's wn and zeta within 1 %
    time_ = np.arange(0, 120, 0.1)
    wn, zeta = 2.0, 0.02
    wd = wn * math.sqrt(1 - zeta**2)
    phi = 0.15 * np.exp(-zeta * wn * time_) * np.cos(wd * time_ + 0.3) + 0.002
    phi += np.random.default_rng(0).normal(0, 1e-4, len(time_))
    fit = bench.linear_decay_fit(time_, phi)
    assert fit["wn"] == pytest.approx(wn, rel=0.01)
    assert fit["zeta"] == pytest.approx(zeta, rel=0.01)


def test_a_refitted_value_is_printed_with_its_std_unless_the_std_swamps_it():
    identified = {"value": -0.124, "std": 0.005, "status": "identified"}
    poor = {"value": -16.9, "std": 12.0, "status": "poorly identified (std 71% of the value)"}
    lost = {"value": 3.08e6, "std": 2e7, "status": "poorly identified (std 649% of the value)"}
    assert bench._final_value("K", identified) == "K=-0.124 ± 0.005"
    assert bench._final_value("T", poor) == "T=-16.9 ± 12 (poorly identified)"
    assert bench._final_value("T", lost) == "T not determined"
    assert bench._final_value("T", {**lost, "std": math.inf}) == "T not determined"
