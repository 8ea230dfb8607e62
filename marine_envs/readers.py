"""Readers of published model-test files into :class:`~marine_envs.recording.Recording`.

The data themselves are not the project's to redistribute (``../shared/data/README``): these
functions read them by path; nothing in the package or its tests needs them.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .recording import Recording

#: Columns of an HSVA zigzag ``.dat`` (0-based): time s; x, y m (earth-fixed); psi deg;
#: dx/dt, dy/dt m/s (EARTH-fixed); r deg/s; roll deg; rudder deg (positive to port); propeller
#: rev/s; thrust N; torque N m.
HSVA_COLUMNS = ("time", "x", "y", "psi", "x_dot", "y_dot", "r", "phi", "delta", "n_p", "thrust",
                "torque")
HSVA_MODELS = ("nomoto", "mmg")


def read_hsva_zigzag(path: str | Path, model: str = "nomoto") -> Recording:
    """An HSVA free-running zigzag ``.dat`` (4 latin-1 header lines, then the 12 columns of
    :data:`HSVA_COLUMNS` at 20 Hz) as a recording of ``model``.

    Both models: input ``delta`` (rad, positive to port, as recorded: it gives a negative r),
    measured ``r`` (rad/s) and ``psi`` (rad, unwrapped, relative to the first sample); time from
    0. The rudder column is the rudder angle itself, not a command: ``meta["measured_inputs"]``
    says so (a delay the diagnosis finds on it is no actuator delay). ``mmg`` adds the input
    ``n_p`` (rev/s, column 10) and the measured body velocities ``u``, ``v`` (m/s): the recorded
    velocities are EARTH-fixed, so they are rotated into the body axes by the recorded
    (absolute) heading, ``u = x_dot cos psi + y_dot sin psi``, ``v = -x_dot sin psi + y_dot cos
    psi`` (at the point the carriage tracks, taken as midship).

    :param path: the ``.dat`` file.
    :param model: ``"nomoto"`` or ``"mmg"``.
    :raises ValueError: an unknown model, or a file without 12 numeric columns.
    """
    if model not in HSVA_MODELS:
        raise ValueError(f"model={model!r} is invalid: one of {', '.join(HSVA_MODELS)}")
    path = Path(path)
    table = np.loadtxt(path, skiprows=4, encoding="latin-1", ndmin=2)
    if table.shape[1] != len(HSVA_COLUMNS):
        raise ValueError(f"{path}: expected {len(HSVA_COLUMNS)} columns "
                         f"({', '.join(HSVA_COLUMNS)}), got shape {table.shape}")
    col = {name: table[:, i] for i, name in enumerate(HSVA_COLUMNS)}
    heading = np.unwrap(np.radians(col["psi"]))
    time = np.round(col["time"] - col["time"][0], 9)
    delta = np.radians(col["delta"])
    measured = {"r": np.radians(col["r"]), "psi": heading - heading[0]}
    meta = {"name": path.name, "measured_inputs": ["delta"] + (["n_p"] if model == "mmg" else [])}
    if model == "nomoto":
        return Recording.from_arrays("nomoto", time, delta, measured, meta=meta)
    c, s = np.cos(heading), np.sin(heading)
    body = {"u": col["x_dot"] * c + col["y_dot"] * s, "v": -col["x_dot"] * s + col["y_dot"] * c}
    return Recording.from_arrays("mmg", time, np.column_stack([delta, col["n_p"]]),
                                 {**body, **measured}, meta=meta)
