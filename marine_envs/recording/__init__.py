"""Recordings: logged runs of a vehicle, real or simulated, in one documented file format.

A recording is a table, stored as CSV or Parquet, plus a little JSON metadata. Rows are samples;
rows are counted from 0 (the CSV header is not a row).

Columns
    ``time``
        Sample time in seconds, strictly increasing. The step must be uniform (every step within a
        relative 1e-3 of the median step) unless the reader is called with
        ``require_uniform=False``.
    one column per model input
        Named as in the model's ``input_names`` (for ``usv``: ``delta``). All are required. The
        input *commanded* (by a controller, a pilot, an excitation signal), as a trial's log
        holds it; what the actuator delivered may differ (a rate limit, a saturation, a delay):
        that goes in an actuator position sensor's column.
    one column per measured channel
        Named as in the model's ``output_names`` (its states, plus derived outputs such as the DP
        vessel's measured position; for ``usv``: ``v, r, psi, p, phi``). Channels that
        were not measured are simply absent, but at least one must be present.
    optional: actuator position sensors
        Named after a model input plus ``_applied`` (for ``usv``: ``delta_applied``), in the
        input's unit: what the actuator delivered, read by a sensor on it (a rudder angle
        indicator), beside the command in the input's own column. Complete, like the inputs.
        A diagnosis judges the map from command to position directly and takes the position
        as the input to the hull (:mod:`estimators.diagnosis.actuators`).
    optional: measured disturbances
        Named as in the model's ``disturbance_names`` (the hovercraft's ``wind_north``, the
        ROV's ``current_n`` or morph command ``s_cmd``): a wind, current or command that was
        logged. A diagnosis takes them as known inputs
        (:class:`~marine_envs.models.MeasuredDisturbances`) instead of estimating them.

    No other columns are allowed and there must be at least two rows. Every value must be a
    finite number, except in the measured channels: there an empty cell or NaN marks a sample
    the logger dropped, a missing measurement (:attr:`Recording.missing`; the filters skip it,
    as they skip a dropped sensor sample). Time, inputs and disturbances must be complete.

Metadata, a JSON object
    ``model`` (required)
        Name of the vehicle model, one of :func:`marine_envs.models.model_names`.
    ``params`` (optional)
        Parameter overrides by docs/models.md symbol, e.g. ``{"wn": 0.7}``; validated by the model.
    ``units`` (optional)
        Unit of each column, e.g. ``{"time": "s", "phi": "deg"}``. Columns not listed are in the
        model's SI units. A unit in :data:`~marine_envs.units.UNIT_CONVERSIONS` (degrees,
        knots, milliseconds, ...) is converted to SI once, when the file is read; any other unit
        must equal the SI unit.
        Files written by :func:`write_recording` are always in SI units and say so.
    any other key
        Free-form information (environment id, seed, dt, policy, ...) that is kept in
        :attr:`Recording.meta` and written back unchanged.

    Parquet stores the metadata in the file's schema metadata under the key ``marine_envs``. CSV
    stores it in a sidecar file named after the data file plus ``.json`` (``run.csv`` ->
    ``run.csv.json``); a sidecar that replaces the suffix (``run.json``) is also read. A CSV without
    sidecar can be read only by naming the model: ``read_recording("run.csv", model="usv")``.

Example, ``run.csv``::

    time,delta,psi,phi
    0.0,0.0,0.0,0.0
    0.1,0.05,0.001,-0.002
    ...

and ``run.csv.json``::

    {"model": "usv", "params": {"wn": 0.7}, "units": {"time": "s", "delta": "deg", "psi": "deg",
     "phi": "deg"}, "seed": 3, "policy": "lqr"}

Reading checks all of the above and raises ``ValueError`` naming the offending column or row.
Values that are legal but implausible for the model (an input beyond twice its bound, an angle
beyond 2 pi: most often a unit mistake) are kept, and listed in :attr:`Recording.warnings` with
the likely mistake; :func:`read_recording` also issues them as
:class:`~marine_envs.plausibility.PlausibilityWarning`.
Parquet support needs pyarrow: ``pip install "marine-envs[parquet]"``.

Writing (:func:`write_recording`, or :func:`stream_recording` for a recording made row by row,
in bounded memory) is whole or nothing: a full disk or an error leaves the earlier file and its
sidecar as they were, never a truncated table or a sidecar that does not match it.
"""

from ..units import UNIT_CONVERSIONS
from .format import APPLIED, METADATA_KEY, RESERVED_KEYS, TIME, UNIFORM_RTOL
from .reading import read_recording
from .record import Recording
from .storage import check_suffix, sidecar
from .writing import CHUNK_ROWS, RecordingStream, stream_recording, write_recording

__all__ = ["APPLIED", "CHUNK_ROWS", "METADATA_KEY", "RESERVED_KEYS", "TIME", "UNIFORM_RTOL",
           "UNIT_CONVERSIONS", "Recording", "RecordingStream", "check_suffix", "read_recording",
           "sidecar", "stream_recording", "write_recording"]
