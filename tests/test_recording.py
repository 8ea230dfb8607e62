"""Tests of the recording format (marine_envs.recording)."""

from __future__ import annotations

import json
import math
import re
import sys

import numpy as np
import pandas as pd
import pytest

from marine_envs.models import MeasuredDisturbances, get_model
from marine_envs.plausibility import PlausibilityWarning
from marine_envs.recording import METADATA_KEY, Recording, read_recording, write_recording

DT = 0.1
META = {"env_id": "marine_envs/USV-v0", "seed": 7, "dt": DT,
        "policy": {"kind": "lqr", "gains": [1.5, -0.25]}}


def make_recording(n: int = 50, channels: tuple[str, ...] = ("r", "psi", "p", "phi"),
                   seed: int = 0, **kwargs) -> Recording:
    rng = np.random.default_rng(seed)
    return Recording.from_arrays("usv", np.arange(n) * DT, rng.normal(size=(n, 1)),
                                 {name: rng.normal(size=n) for name in channels}, **kwargs)


def make_frame(n: int = 10) -> pd.DataFrame:
    """A valid usv table with psi and phi measured."""
    rng = np.random.default_rng(1)
    return pd.DataFrame({"time": np.arange(n) * DT, "delta": rng.normal(size=n),
                         "psi": rng.normal(size=n), "phi": rng.normal(size=n)})


def write_csv(tmp_path, frame: pd.DataFrame, metadata: dict | None, name: str = "run.csv"):
    path = tmp_path / name
    frame.to_csv(path, index=False)
    if metadata is not None:
        path.with_name(name + ".json").write_text(json.dumps(metadata))
    return path


# -- round trips -------------------------------------------------------------------------------
@pytest.mark.parametrize("suffix", [".csv", ".parquet"])
def test_round_trip_keeps_values_model_params_units_and_meta(tmp_path, suffix):
    if suffix == ".parquet":
        pytest.importorskip("pyarrow")
    original = make_recording(params={"wn": 0.7, "zeta": 0.2}, meta=META)
    path = write_recording(original, tmp_path / f"run{suffix}")
    assert path == tmp_path / f"run{suffix}"

    back = read_recording(path)

    assert list(back.data.columns) == ["time", "delta", "r", "psi", "p", "phi"]
    np.testing.assert_array_equal(back.data.to_numpy(), original.data.to_numpy())
    assert back.model == "usv"
    assert back.params == {"wn": 0.7, "zeta": 0.2}
    assert back.meta == META
    assert back.units == {"time": "s", "delta": "rad", "r": "rad/s", "psi": "rad", "p": "rad/s",
                          "phi": "rad"}


def test_views_follow_model_order():
    rec = Recording(make_frame()[["phi", "delta", "psi", "time"]], "usv")
    assert list(rec.data.columns) == ["time", "delta", "psi", "phi"]
    assert rec.input_names == ("delta",)
    assert rec.measured_names == ("psi", "phi")
    np.testing.assert_array_equal(rec.measurements, make_frame()[["psi", "phi"]].to_numpy())
    np.testing.assert_array_equal(rec.inputs, make_frame()[["delta"]].to_numpy())
    np.testing.assert_array_equal(rec.time, np.arange(10) * DT)
    assert rec.dt == pytest.approx(DT)


def test_csv_writes_sidecar_named_after_the_file(tmp_path):
    write_recording(make_recording(meta={"seed": 3}), tmp_path / "run.csv")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.csv", "run.csv.json"]
    sidecar = json.loads((tmp_path / "run.csv.json").read_text())
    assert sidecar["model"] == "usv"
    assert sidecar["units"]["phi"] == "rad"
    assert sidecar["seed"] == 3


def test_parquet_keeps_metadata_in_schema_next_to_pandas_metadata(tmp_path):
    pq = pytest.importorskip("pyarrow.parquet")
    path = write_recording(make_recording(meta={"seed": 3}), tmp_path / "run.parquet")
    schema_metadata = pq.read_schema(path).metadata
    assert json.loads(schema_metadata[METADATA_KEY.encode()])["seed"] == 3
    assert b"pandas" in schema_metadata
    assert [p.name for p in tmp_path.iterdir()] == ["run.parquet"]


def test_numpy_scalars_in_meta_are_written_as_json(tmp_path):
    rec = make_recording(meta={"seed": np.int64(5), "dt": np.float32(0.5)})
    assert read_recording(write_recording(rec, tmp_path / "run.csv")).meta == {"seed": 5,
                                                                              "dt": 0.5}


def test_unserialisable_meta_fails_before_writing_anything(tmp_path):
    with pytest.raises(TypeError, match="not JSON-serialisable"):
        write_recording(make_recording(meta={"policy": object()}), tmp_path / "run.csv")
    assert list(tmp_path.iterdir()) == []


def test_reads_sidecar_that_replaces_the_suffix(tmp_path):
    path = write_recording(make_recording(meta={"seed": 3}), tmp_path / "run.csv")
    (tmp_path / "run.csv.json").rename(tmp_path / "run.json")
    assert read_recording(path).meta == {"seed": 3}


def test_canonical_sidecar_wins_over_stem_sidecar(tmp_path):
    path = write_recording(make_recording(), tmp_path / "run.csv")
    (tmp_path / "run.json").write_text(json.dumps({"model": "hydrofoil"}))
    assert read_recording(path).model == "usv"


def test_csv_without_sidecar_needs_model(tmp_path):
    path = write_csv(tmp_path, make_frame(), None)
    with pytest.raises(ValueError, match=r"run\.csv\.json.*model="):
        read_recording(path)
    rec = read_recording(path, model="usv")
    assert (rec.model, rec.params, rec.meta) == ("usv", {}, {})
    np.testing.assert_array_equal(rec.data.to_numpy(), make_frame().to_numpy())


def test_parquet_without_metadata_needs_model(tmp_path):
    pytest.importorskip("pyarrow")
    path = tmp_path / "run.parquet"
    make_frame().to_parquet(path, engine="pyarrow", index=False)
    with pytest.raises(ValueError, match="model="):
        read_recording(path)
    assert read_recording(path, model="usv").measured_names == ("psi", "phi")


def test_single_measured_channel_is_accepted(tmp_path):
    rec = make_recording(channels=("phi",))
    assert rec.measured_names == ("phi",)
    assert rec.measurements.shape == (50, 1)
    back = read_recording(write_recording(rec, tmp_path / "run.csv"))
    assert list(back.data.columns) == ["time", "delta", "phi"]


# -- units -------------------------------------------------------------------------------------
def test_non_si_units_are_converted_once_at_read_time(tmp_path):
    frame = pd.DataFrame({"time": [0, 100, 200], "delta": [10.0, 0.0, -10.0],
                          "v": [1.0, 2.0, 0.0], "phi": [90.0, -45.0, 0.0]})
    units = {"time": "ms", "delta": "deg", "v": "kn", "phi": "deg"}
    path = write_csv(tmp_path, frame, {"model": "usv", "units": units})

    rec = read_recording(path)

    np.testing.assert_allclose(rec.time, [0.0, 0.1, 0.2], rtol=1e-15)
    assert rec.data["phi"].iloc[0] == pytest.approx(math.pi / 2, rel=1e-15)
    assert rec.data["delta"].iloc[0] == pytest.approx(math.radians(10), rel=1e-15)
    assert rec.data["v"].iloc[0] == pytest.approx(1852 / 3600, rel=1e-15)
    assert rec.units == {"time": "s", "delta": "rad", "v": "m/s", "phi": "rad"}
    # Written back in SI and labelled so: a second read must not convert again.
    again = read_recording(write_recording(rec, tmp_path / "si.csv"))
    np.testing.assert_array_equal(again.data.to_numpy(), rec.data.to_numpy())


@pytest.mark.parametrize(("column", "unit", "si"), [
    ("phi", "m/s", "rad"),  # known unit, wrong dimension
    ("v", "deg/s", "m/s"),
    ("time", "furlong", "s"),  # unknown unit
])
def test_unconvertible_unit_names_column_unit_and_si_unit(tmp_path, column, unit, si):
    frame = make_frame().assign(v=0.0)
    path = write_csv(tmp_path, frame, {"model": "usv", "units": {column: unit}})
    with pytest.raises(ValueError) as info:
        read_recording(path)
    assert f"{column!r}" in str(info.value)
    assert f"{unit!r}" in str(info.value)
    assert f"SI unit {si!r}" in str(info.value)


def test_units_for_unknown_column_are_rejected(tmp_path):
    path = write_csv(tmp_path, make_frame(), {"model": "usv", "units": {"heave": "m"}})
    with pytest.raises(ValueError, match="heave"):
        read_recording(path)


# -- validation errors -------------------------------------------------------------------------
def _set(frame: pd.DataFrame, column: str, row: int, value) -> pd.DataFrame:
    frame = frame.astype({column: object}) if isinstance(value, str) else frame
    frame.loc[row, column] = value
    return frame


INVALID = {
    "missing time": (lambda f: f.drop(columns="time"), [r"'time'"]),
    "missing input": (lambda f: f.drop(columns="delta"), [r"input.*'delta'"]),
    "unknown column": (lambda f: f.assign(rudder=0.0),
                       [r"unknown column.*'rudder'", r"allowed: time, delta, v, r, psi, p, phi"]),
    "no measured channel": (lambda f: f.drop(columns=["psi", "phi"]),
                            [r"no measured channel", r"v, r, psi, p, phi"]),
    "non-numeric": (lambda f: _set(f, "psi", 2, "abc"), [r"'psi'", r"not numeric", r"row 2"]),
    "nan input": (lambda f: _set(f, "delta", 3, np.nan),
                  [r"'delta'", r"nan", r"row 3", r"time 0\.3 s"]),
    "inf measurement": (lambda f: _set(f, "phi", 3, np.inf), [r"'phi'", r"inf", r"row 3"]),
    "no measurement": (lambda f: f.assign(phi=np.nan), [r"'phi' has no value"]),
    "inf": (lambda f: _set(f, "delta", 4, -np.inf), [r"'delta'", r"-inf", r"row 4"]),
    "nan time": (lambda f: _set(f, "time", 1, np.nan), [r"'time'", r"row 1"]),
    "repeated time": (lambda f: _set(f, "time", 5, 0.4),
                      [r"not strictly increasing at row 5", r"0\.4 s follows 0\.4 s at row 4"]),
    "decreasing time": (lambda f: _set(f, "time", 5, 0.35),
                        [r"row 5", r"0\.35 s follows 0\.4 s"]),
    # Steps of 0.1 s except 0.102 s into row 6: 2 % off the median, tolerance 0.1 %.
    "non-uniform step": (lambda f: f.assign(time=np.r_[np.arange(6), np.arange(6, 10) + 0.02] * DT),
                         [r"non-uniform time step at row 6", r"step 0\.102 s",
                          r"expected 0\.1 s", r"require_uniform=False"]),
    "one row": (lambda f: f.iloc[:1], [r"1 row", r"at least 2"]),
    "no rows": (lambda f: f.iloc[:0], [r"0 row"]),
}


@pytest.mark.parametrize("case", INVALID)
def test_invalid_table_raises_naming_column_or_row(case):
    mutate, patterns = INVALID[case]
    with pytest.raises(ValueError) as info:
        Recording(mutate(make_frame()), "usv")
    for pattern in patterns:
        assert re.search(pattern, str(info.value)), (pattern, str(info.value))


def test_read_validates_and_names_file_and_row(tmp_path):
    text = "time,delta,phi\n0.0,0.0,0.0\n0.1,,0.0\n0.2,0.0,0.0\n"  # empty input cell: row 1
    path = tmp_path / "run.csv"
    path.write_text(text)
    with pytest.raises(ValueError, match=r"run\.csv: column 'delta' .* row 1 \(time 0\.1 s\)"):
        read_recording(path, model="usv")


def test_a_dropped_measurement_is_missing_not_an_error(tmp_path):
    path = tmp_path / "run.csv"  # empty cell and NaN: samples the logger dropped
    path.write_text("time,delta,psi,phi\n0.0,0.0,0.0,0.0\n0.1,0.0,,0.2\n0.2,0.0,0.2,nan\n"
                    "0.3,0.0,0.3,0.3\n")
    rec = read_recording(path, model="usv")
    np.testing.assert_array_equal(rec.missing, [[False, False], [True, False], [False, True],
                                                [False, False]])
    filled = rec.filled()  # linear in time between the neighbours, and marked
    np.testing.assert_allclose(filled.measurements, [[0, 0], [0.1, 0.2], [0.2, 0.25],
                                                     [0.3, 0.3]])
    np.testing.assert_array_equal(filled.gaps, rec.missing)
    write_recording(rec, tmp_path / "again.csv")  # written back as empty cells
    np.testing.assert_array_equal(read_recording(tmp_path / "again.csv").missing, rec.missing)


def test_window_cuts_and_decimates_on_the_records_clock():
    n = 100
    rec = Recording.from_arrays("usv", np.arange(n) * DT, np.zeros(n), {"phi": np.arange(n)})
    cut = rec.window(start=2.0, stop=5.0, decimate=3)
    np.testing.assert_allclose(cut.time, [2.0, 2.3, 2.6, 2.9, 3.2, 3.5, 3.8, 4.1, 4.4, 4.7, 5.0])
    assert cut.meta["window"] == {"start": 2.0, "stop": 5.0, "decimate": 3}
    with pytest.raises(ValueError, match=r"decimate=0 is invalid"):
        rec.window(decimate=0)
    with pytest.raises(ValueError, match=r"leave 1 sample\(s\)"):
        rec.window(start=9.85)
    with pytest.raises(ValueError, match=r"start < stop"):
        rec.window(start=5.0, stop=2.0)


@pytest.mark.parametrize("column, unit, values, text", [
    ("delta", "rad", np.radians(35) * 57.3, r"delta: 35 exceeds the model's bound 0\.611 rad by "
                                            r"57x: degrees declared as rad\?"),
    ("delta", "deg", 0.5, r"delta: 0\.00873 rad is 1\.4% of the model's bound 0\.611 rad: "
                          r"radians declared as deg\?"),
    ("phi", "rad", 30.0, r"phi: 30 rad exceeds 2 pi: degrees declared as rad\?"),
])
def test_implausible_units_are_named_with_the_likely_mistake(tmp_path, column, unit, values, text):
    n, wave = 50, np.sin(np.linspace(0, 6, 50)) / np.sin(np.linspace(0, 6, 50)).max()
    frame = pd.DataFrame({"time": np.arange(n) * DT, "delta": 0.1 * wave, "psi": 0.2 * wave,
                          "phi": 0.05 * wave})  # plausible in radians
    frame[column] = values * wave
    path = tmp_path / "run.csv"
    frame.to_csv(path, index=False)
    (tmp_path / "run.csv.json").write_text(json.dumps({"model": "usv", "units": {column: unit}}))
    with pytest.warns(PlausibilityWarning, match=r"run\.csv: " + text):
        rec = read_recording(path)
    assert len(rec.warnings) == 1 and re.search(text, rec.warnings[0])


def test_read_reports_non_numeric_cell(tmp_path):
    path = tmp_path / "run.csv"
    path.write_text("time,delta,phi\n0.0,0.0,0.0\n0.1,0.0,0.0\n0.2,oops,0.0\n")
    with pytest.raises(ValueError, match=r"'delta' is not numeric.*row 2 is 'oops'"):
        read_recording(path, model="usv")


def test_non_uniform_sampling_accepted_on_request(tmp_path):
    time = np.array([0.0, 0.1, 0.2, 0.35, 0.4, 0.5])  # median step 0.1 s, off from row 3
    rec = Recording.from_arrays("usv", time, np.zeros(6), {"phi": np.zeros(6)},
                                require_uniform=False)
    np.testing.assert_array_equal(rec.time, time)
    path = write_recording(rec, tmp_path / "run.csv")
    with pytest.raises(ValueError, match="non-uniform time step at row 3"):
        read_recording(path)
    np.testing.assert_array_equal(read_recording(path, require_uniform=False).time, time)


def test_non_uniform_sampling_must_still_increase():
    with pytest.raises(ValueError, match="not strictly increasing at row 2"):
        Recording.from_arrays("usv", [0.0, 0.2, 0.1], np.zeros(3), {"phi": np.zeros(3)},
                              require_uniform=False)


def test_small_time_jitter_is_uniform():
    time = np.arange(100) * DT + np.random.default_rng(2).uniform(-2e-5, 2e-5, 100)
    assert Recording.from_arrays("usv", time, np.zeros(100), {"phi": np.zeros(100)}).dt == \
        pytest.approx(DT, rel=1e-3)


@pytest.mark.parametrize(("inputs", "measurements", "pattern"), [
    (np.zeros((5, 2)), {"phi": np.zeros(5)}, r"inputs must have shape \(n, 1\).*delta"),
    (np.zeros(5), {"phi": np.zeros(4)}, r"'phi' must have shape \(5,\)"),
    (np.zeros(5), {"heave": np.zeros(5)}, r"unknown measured channel.*'heave'.*psi"),
    (np.zeros(5), {}, r"no measured channel"),
])
def test_from_arrays_rejects_bad_shapes_and_names(inputs, measurements, pattern):
    with pytest.raises(ValueError, match=pattern):
        Recording.from_arrays("usv", np.arange(5) * DT, inputs, measurements)


def test_reserved_meta_key_is_rejected():
    with pytest.raises(ValueError, match="'model'"):
        make_recording(meta={"model": "usv"})


def test_recording_copies_the_data():
    frame = make_frame()
    rec = Recording(frame, "usv")
    frame.loc[0, "phi"] = 99.0
    assert rec.data.loc[0, "phi"] != 99.0


# -- model and parameters ----------------------------------------------------------------------
def test_wrong_model_is_rejected(tmp_path):
    path = write_recording(make_recording(), tmp_path / "run.csv")
    with pytest.raises(ValueError, match="recording is for model 'usv', not 'rov'"):
        read_recording(path, model="rov")
    assert read_recording(path, model="usv").model == "usv"


def test_unknown_model_lists_known_models(tmp_path):
    path = write_csv(tmp_path, make_frame(), {"model": "submarine"})
    with pytest.raises(ValueError, match=r"'submarine'.*usv"):
        read_recording(path)
    with pytest.raises(ValueError, match=r"'submarine'.*usv"):
        Recording.from_arrays("submarine", [0.0, 0.1], [0.0, 0.0], {"phi": [0.0, 0.0]})


@pytest.mark.parametrize("params", [{"wn": -1}, {"wn": "fast"}, {"wn_typo": 1.0}])
def test_invalid_parameter_in_metadata_is_named(tmp_path, params):
    path = write_csv(tmp_path, make_frame(), {"model": "usv", "params": params})
    with pytest.raises(ValueError, match=next(iter(params))):
        read_recording(path)


def test_parameters_reach_the_model(tmp_path):
    path = write_csv(tmp_path, make_frame(), {"model": "usv", "params": {"wn": 0.7}})
    rec = read_recording(path)
    assert get_model(rec.model, **rec.params).params.wn == 0.7


# -- files and formats -------------------------------------------------------------------------
def test_missing_file_names_the_path(tmp_path):
    path = tmp_path / "absent.csv"
    with pytest.raises(FileNotFoundError, match="absent.csv"):
        read_recording(path, model="usv")


@pytest.mark.parametrize("name", ["run.txt", "run.csv.gz", "run"])
def test_unsupported_suffix_is_named(tmp_path, name):
    suffix = (tmp_path / name).suffix
    with pytest.raises(ValueError, match=f"unsupported recording suffix '{re.escape(suffix)}'"):
        write_recording(make_recording(), tmp_path / name)
    with pytest.raises(ValueError, match="unsupported recording suffix"):
        read_recording(tmp_path / name)
    assert list(tmp_path.iterdir()) == []


def test_parquet_without_pyarrow_gives_install_hint(tmp_path, monkeypatch):
    pytest.importorskip("pyarrow")
    existing = write_recording(make_recording(), tmp_path / "old.parquet")
    monkeypatch.setitem(sys.modules, "pyarrow", None)  # makes `import pyarrow` fail
    monkeypatch.setitem(sys.modules, "pyarrow.parquet", None)
    hint = re.escape('pip install "marine-envs[parquet]"')
    with pytest.raises(ImportError, match=hint):
        write_recording(make_recording(), tmp_path / "new.parquet")
    with pytest.raises(ImportError, match=hint):
        read_recording(existing)
    # CSV does not need pyarrow.
    csv = write_recording(make_recording(), tmp_path / "run.csv")
    assert read_recording(csv).model == "usv"


# -- measured disturbances ---------------------------------------------------------------------
def test_a_measured_wind_is_a_column_of_its_own_in_si_units(tmp_path):
    frame = pd.DataFrame({"time": [0.0, 0.1, 0.2], "sigma_1": 0.5, "sigma_2": 0.5, "delta": 0.0,
                          "wind_east": [10.0, 12.0, 8.0], "u": [5.0, 5.1, 5.2]})
    path = write_csv(tmp_path, frame, {"model": "hovercraft", "units": {"wind_east": "kn"}})

    rec = read_recording(path)

    assert rec.disturbance_names == ("wind_east",)
    assert list(rec.data.columns) == ["time", "sigma_1", "sigma_2", "delta", "wind_east", "u"]
    assert rec.units["wind_east"] == "m/s"
    np.testing.assert_allclose(rec.data["wind_east"], np.array([10.0, 12.0, 8.0]) * 1852 / 3600)
    assert rec.inputs.shape == (3, 3)  # the actuators only
    model = MeasuredDisturbances(get_model("hovercraft"), rec.disturbance_names)
    np.testing.assert_array_equal(rec.inputs_for(model)[:, 3], rec.data["wind_east"])
    with pytest.raises(ValueError, match=r"unknown disturbance\(s\) \['gust'\]"):
        Recording.from_arrays("hovercraft", rec.time, rec.inputs, {"u": rec.data["u"]},
                              disturbances={"gust": rec.data["wind_east"]})


def test_a_model_with_measured_disturbances_takes_them_as_inputs():
    rov = get_model("rov")
    model = MeasuredDisturbances(rov, ("s_cmd", "current_n"))
    assert model.input_names == (*rov.input_names, "s_cmd", "current_n")
    assert model.actuator_names == rov.input_names
    assert model.disturbance_names == ("current_e", "current_d")
    assert model.environment_disturbances == ("current_e", "current_d")
    rng = np.random.default_rng(3)
    x, u, d = rov.x0 + 0.1 * rng.normal(size=(5, 13)), rov.u0 + rng.normal(size=(5, 6)), \
        rng.normal(size=(5, 4))
    np.testing.assert_array_equal(model.rhs(x, np.c_[u, d[:, 3], d[:, 0]], d[:, 1:3]),
                                  rov.rhs(x, u, d))
    assert model.with_params(m=40.0).model.params.m == 40.0
    with pytest.raises(ValueError, match=r"give distinct names of current_n"):
        MeasuredDisturbances(rov, ("wind",))


def test_a_streamed_recording_is_checked_row_by_row_and_written_whole(tmp_path):
    from marine_envs.recording import stream_recording

    path = tmp_path / "run.csv"
    # any column order in, the format's order out; chunks of 2 rows
    with stream_recording(path, "usv", ["phi", "time", "delta"], meta={"seed": 1},
                          chunk_rows=2) as stream:
        for k in range(5):
            stream.append([0.01 * k, 0.1 * k, -0.02 * k])
        assert not path.exists()  # only when whole
        stream.meta["stopped"] = "done"  # the metadata may change until the end
    written = read_recording(path)
    assert list(written.data.columns) == ["time", "delta", "phi"]
    np.testing.assert_array_equal(written.data["phi"], 0.01 * np.arange(5))
    assert written.meta == {"seed": 1, "stopped": "done"}
    earlier = path.read_bytes()
    with pytest.raises(ValueError, match="column 'delta' has non-finite value inf at row 3"):
        with stream_recording(path, "usv", ["time", "delta", "phi"], chunk_rows=2) as stream:
            for k, delta in enumerate([0.0, 0.0, 0.0, math.inf]):
                stream.append([0.1 * k, delta, 0.0])
    with pytest.raises(ValueError, match="time is not strictly increasing at row 2"):
        with stream_recording(path, "usv", ["time", "delta", "phi"], chunk_rows=2) as stream:
            stream.extend([[0.0, 0, 0], [0.1, 0, 0], [0.1, 0, 0]])
    with pytest.raises(ValueError, match="1 row"):
        with stream_recording(path, "usv", ["time", "delta", "phi"]) as stream:
            stream.append([0.0, 0.0, 0.0])
    assert path.read_bytes() == earlier  # the recording before, whole
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.csv", "run.csv.json"]
