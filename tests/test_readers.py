"""marine_envs.readers: the HSVA zigzag reader on a tiny synthetic file (never the shared data)."""

import math

import numpy as np
import pytest

from marine_envs.readers import read_hsva_zigzag


def _hsva_file(path, psi_deg, x_dot, y_dot):
    """4 latin-1 header lines, then 12 columns at 20 Hz (time from 3 s)."""
    rows = [[3.0 + 0.05 * k, 1.0 + k, 0.1, psi_deg[k], x_dot[k], y_dot[k], 10.0, 0.2, 5.0,
             10.23, 41.0, 1.0] for k in range(len(psi_deg))]
    path.write_bytes(" HSVA\n KVLCC2\n Z10\xb0/10\xb0\n Time series\n".encode("latin-1")
                     + "\n".join(" ".join(f"{v:.9f}" for v in row) for row in rows).encode())
    return path


def test_mmg_recording_has_body_velocities_rotated_from_the_earth_fixed_ones(tmp_path):
    # a ship heading 30 deg (then crossing +-180 deg) with body velocities u = 1.2, v = -0.05
    psi_deg = np.array([30.0, 31.0, 179.5, -180.0, -179.5])
    psi = np.radians(psi_deg)
    u, v = 1.2, -0.05
    x_dot = u * np.cos(psi) - v * np.sin(psi)
    y_dot = u * np.sin(psi) + v * np.cos(psi)
    rec = read_hsva_zigzag(_hsva_file(tmp_path / "Z.dat", psi_deg, x_dot, y_dot), model="mmg")
    assert rec.model == "mmg" and set(rec.measured_names) == {"u", "v", "r", "psi"}
    np.testing.assert_allclose(rec.data["u"], u, atol=1e-8)
    np.testing.assert_allclose(rec.data["v"], v, atol=1e-8)  # not x_dot, y_dot: rotated
    np.testing.assert_allclose(rec.inputs[:, 0], math.radians(5.0))  # rudder: sign kept
    np.testing.assert_allclose(rec.inputs[:, 1], 10.23)  # propeller rev/s, column 10
    np.testing.assert_allclose(rec.data["r"], math.radians(10.0))
    # heading relative to the first sample and unwrapped through +-180 deg
    np.testing.assert_allclose(rec.data["psi"], np.radians([0.0, 1.0, 149.5, 150.0, 150.5]),
                               atol=1e-12)
    np.testing.assert_allclose(rec.time, 0.05 * np.arange(5), atol=1e-12)


def test_nomoto_recording_and_bad_input(tmp_path):
    path = _hsva_file(tmp_path / "Z.dat", [0.0, 0.5, 1.0], [1.18] * 3, [0.0] * 3)
    rec = read_hsva_zigzag(path)
    assert rec.model == "nomoto" and rec.measured_names == ("r", "psi")
    assert rec.inputs.shape == (3, 1)
    with pytest.raises(ValueError, match="model='usv' is invalid"):
        read_hsva_zigzag(path, model="usv")
    short = tmp_path / "short.dat"
    short.write_text("a\nb\nc\nd\n1 2 3\n4 5 6\n")
    with pytest.raises(ValueError, match="expected 12 columns"):
        read_hsva_zigzag(short)
