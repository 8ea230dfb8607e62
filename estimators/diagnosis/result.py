"""What a diagnosis answers: :class:`Diagnosis` (the documented JSON, a terminal summary) and its
:class:`Finding` entries, shared by both ways of judging a record (:mod:`.api`)."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from marine_envs.files import write_text
from marine_envs.models.effects import Effect
from marine_envs.vessel import VesselDescription, read_effects

from .residuals import Forcing, Residuals, Sea
from .rollout import Rollouts
from .selection import Selection


@dataclass
class Finding:
    """One effect the recording supports (the JSON's ``findings`` entries).

    :param effect: catalogue name.  :param target: state, input or channel it acts on.
    :param parameters: fitted values (SI units, the catalogue's sign convention).
    :param std: their standard deviations.  :param confidence: in [0, 1].
    :param improvement: held-out share of the excess prediction error this term removes alone.
    :param explanation: what it means, in words.
    :param withdrawn: why it is not confirmed (the ``unconfirmed`` entries), or ``""``.
    :param fitted_range: ``{name: [low, high]}`` (model units) of the states its term acts on,
        or of an input effect's input, over the records it was fitted on (free simulation).
    :param named_as: what it really is when its catalogue name would mislead (a constant force
        an offset parameter of the model explains; an actuator effect on a measured input).
    """

    effect: str
    target: str
    parameters: dict[str, Any]
    std: dict[str, float]
    confidence: float
    improvement: float
    explanation: str
    standard_form: dict[str, float] = field(default_factory=dict)
    withdrawn: str = ""
    fitted_range: dict[str, list[float]] = field(default_factory=dict)
    named_as: dict[str, Any] = field(default_factory=dict)
    #: per parameter: its spread between records (or pieces of one) beside the statistical std
    #: (then ``std`` holds the larger of the two)
    between_records: dict[str, dict[str, Any]] = field(default_factory=dict)

    def as_effect(self) -> Effect:
        return Effect(self.effect, self.target, self.parameters)


@dataclass
class Diagnosis:
    """The answer of :func:`diagnose`; :meth:`to_dict` is the documented JSON.

    ``mismatch`` is True when a finding is claimed, False when nothing significant is found and
    None when the recording cannot be judged (``reason`` says why).
    """

    model: str
    mismatch: bool | None
    reason: str = ""
    channels: list[dict[str, Any]] = field(default_factory=list)
    windows: list[dict[str, Any]] = field(default_factory=list)
    band: dict[str, float] | None = None
    findings: list[Finding] = field(default_factory=list)
    unconfirmed: list[Finding] = field(default_factory=list)
    fit: dict[str, Any] = field(default_factory=dict)
    calibration: dict[str, float] = field(default_factory=dict)
    #: the nominal parameter overrides the diagnosis started from (the first recording's
    #: metadata and ``params``): with ``calibration``, what rebuilds its models (``marine
    #: validate``)
    params: dict[str, float] = field(default_factory=dict)
    model_check: dict[str, Any] = field(default_factory=dict)
    calibration_quality: dict[str, Any] = field(default_factory=dict)
    unexplained: dict[str, Any] = field(default_factory=dict)
    alternatives: list[dict[str, Any]] = field(default_factory=list)
    #: leave-one-amplitude-class-out validation of a model-test series (:mod:`.spread`)
    across_classes: dict[str, Any] = field(default_factory=dict)
    #: with ``unexplained``: the candidates of the search's last round and why none was kept
    not_kept: list[dict[str, Any]] = field(default_factory=list)
    #: candidates refused because their sign makes the motion less stable (free simulation)
    non_physical: list[dict[str, Any]] = field(default_factory=list)
    #: recorded disturbances the model took as known inputs (a logged wind, current, command)
    measured_disturbances: tuple[str, ...] = ()
    #: the recordings' implausible values (unit mistakes?), one line each
    warnings: list[str] = field(default_factory=list)
    #: samples a logger dropped per channel (NaN in the record), taken as missing measurements
    missing_samples: dict[str, int] = field(default_factory=dict)
    #: how a record in a seaway was sized before the work (:mod:`.sizing`): ``decimated``
    #: (factor, step) and ``cut`` (start, stop, samples), each with its reason; empty: whole
    record: dict[str, Any] = field(default_factory=dict)
    residuals: Residuals | None = field(default=None, repr=False)
    rollouts: Rollouts | None = field(default=None, repr=False)
    selection: Selection | None = field(default=None, repr=False)
    comparison: Any = field(default=None, repr=False)  # .comparison.Comparison (model tests)

    def to_dict(self) -> dict[str, Any]:
        """The JSON document (see the issue's schema), with plain Python numbers; also
        ``unconfirmed`` findings, the ``calibration`` and the ``noise_model`` (the coloured
        forcing: each environment channel the filter estimated, its steady part and std in
        its units, and each force equation's own, std in state units per s; correlation
        times, s; and the sea driving several equations as one process); and the diagnosed
        vessel as an environment reads it (``environment``: :meth:`environment`, or
        ``environment_refused``: why there is none)."""
        out = {"model": self.model, "mismatch": self.mismatch, "channels": self.channels,
               "windows": self.windows, "band": self.band,
               "findings": [_finding_dict(f) for f in self.findings], "fit": self.fit}
        if self.unconfirmed:
            out["unconfirmed"] = [_finding_dict(f) for f in self.unconfirmed]
        if self.reason:
            out["reason"] = self.reason
        if self.calibration:
            out["calibration"] = self.calibration
        if self.params:
            out["params"] = self.params
        for key in ("calibration_quality", "model_check", "unexplained", "not_kept",
                    "alternatives", "non_physical", "across_classes"):
            if getattr(self, key):
                out[key] = getattr(self, key)
        if self.mismatch is not None:
            try:
                out["environment"] = self.environment().to_dict()
            except ValueError as error:  # not a registered vehicle, a value out of range
                out["environment_refused"] = str(error)
        if self.measured_disturbances:
            out["measured_disturbances"] = list(self.measured_disturbances)
        for key in ("warnings", "missing_samples", "record"):
            if getattr(self, key):
                out[key] = getattr(self, key)
        res = self.residuals
        if res is not None and (res.forcing or res.sea is not None):
            out["noise_model"] = [_forcing_dict(f, res.model) for f in res.forcing] + (
                [] if res.sea is None else [_sea_dict(res.sea, res.model)])
        return json.loads(json.dumps(out, default=_plain))

    def environment(self) -> VesselDescription:
        """The diagnosed vessel as an environment takes it (``effects=``, the JSON's
        ``environment``, :mod:`marine_envs.vessel`): the parameters the diagnosis started from
        (:attr:`params`) overridden by the calibrated ones (refitted with the findings when
        there are findings), and the findings an environment can carry (the others in its
        ``left_out``, with the reason).

        :raises ValueError: the model is not a registered vehicle, or a calibrated value is
            out of its parameter's range.
        """
        refitted = {name: q["value"] for name, q in
                    self.calibration_quality.get("with_findings", {}).items()}
        params = {**self.params, **self.calibration, **refitted}
        effects = read_effects([_finding_dict(f) for f in self.findings])
        return VesselDescription.carrying(self.model, params, effects)

    def to_json(self, path: str | Path | None = None) -> str:
        text = json.dumps(self.to_dict(), indent=2)
        if path is not None:
            write_text(path, text + "\n")  # whole or not at all
        return text

    def summary(self) -> str:
        """A few lines for a terminal."""
        if self.mismatch is None:
            return f"{self.model}: cannot diagnose: {self.reason}"
        withdrawn = [f"  withdrawn: {f.effect} on {f.target} (improvement {f.improvement:.0%}): "
                     + (f.withdrawn or "not confirmed on held-out data")
                     for f in self.unconfirmed]
        lines = [f"  calibrated {n} = {_fmt(q['value'])}"
                 + (f" ± {_fmt(q['std'])}" if "std" in q else "") + f": {q['status']}"
                 for n, q in self.calibration_quality.get("parameters", {}).items()]
        lines += [f"  {' and '.join(c['parameters'])}: correlation {c['correlation']:+.3f}, "
                  f"{c['status']}" for c in self.calibration_quality.get("correlations", [])]
        lines += [f"  refitted with the findings, {n} is {q['status']}"
                  for n, q in self.calibration_quality.get("with_findings", {}).items()
                  if q["status"] != "identified"]
        if self.measured_disturbances:
            lines.append("  recorded disturbances taken as known inputs: "
                         + ", ".join(self.measured_disturbances))
        if not self.mismatch:
            return "\n".join([f"{self.model}: no significant mismatch: the nominal model "
                              "explains the record", *lines, *withdrawn])
        lines.insert(0, f"{self.model}: mismatch found" if self.findings else
                     f"{self.model}: mismatch, unexplained by the catalogue")
        for k, f in enumerate(self.findings, 1):
            values = ", ".join(f"{n}={_fmt(v)}" + (f" ± {_fmt(f.std[n])}" if n in f.std else "")
                               for n, v in f.parameters.items())
            lines.append(f"  {k}. {f.effect} on {f.target} ({values}), confidence "
                         f"{f.confidence:.2f}: {f.explanation}")
        improvement = self.fit.get("improvement", 0)
        if self.findings:
            lines.append("  held-out improvement: " + (improvement if isinstance(
                improvement, str) else f"{improvement:.0%}"))
            sea = self.fit.get("expected_from_sea", 0)
            if sea >= 0.5:
                lines.append(f"  (the model's own sea model expects {sea:.0%} of the held-out "
                             "prediction error: the improvement is measured against it)")
        holding = self.model_check.get("worse_than_holding")
        if holding:
            lines.append(f"  (the nominal model alone predicts {holding['nominal']:.1f}x worse "
                         "than holding the last sample; with the findings "
                         f"{holding['with_findings']:.1f}x)")
        for channel, left in self.unexplained.items():
            lines.append(f"  unexplained in {channel}: {_with_unit(left['rmse'], left['unit'])}"
                         f" RMS held-out ({left['share_of_signal']:.0%} of the signal)")
        lines += [f"  not kept: {tried['candidate']} ({_gain(tried['improvement'])}): "
                  f"{tried['reason']}" for tried in self.not_kept]
        for alt in self.alternatives:
            values = ", ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}"
                               for k, v in alt.get("parameters", {}).items())
            lines.append(f"  {alt['equally']}{f' ({values})' if values else ''} explains the "
                         f"data as well as {alt['chosen']}; to separate them: "
                         f"{alt['separate_by']}")
        return "\n".join(lines + withdrawn)


def _gain(share: float | str) -> str:
    """A held-out improvement as words: "removes 33%", "removes nothing", "worse by 51%" or
    "diverged"."""
    if isinstance(share, str):
        return share
    if abs(share) < 0.005:
        return "removes nothing"
    return f"removes {share:.0%}" if share > 0 else f"worse by {-share:.0%}"


def _forcing_dict(f: Forcing, model: Any) -> dict[str, Any]:
    tau, std = f.tau, math.sqrt(f.variance)
    if f.disturbance is None:
        return {"equation": model.state_names[f.state], "correlation_time": tau, "std": std}
    return {"disturbance": model.disturbance_names[f.disturbance],
            "unit": model.disturbance_units[f.disturbance], "steady": f.level,
            "correlation_time": tau, "std": std,
            "equations": [model.state_names[i] for i in f.equations]}


def _sea_dict(sea: Sea, model: Any) -> dict[str, Any]:
    """The sea of the noise model: its peak frequency (rad/s), damping ratio, and per equation
    its std (state units per s) and phase (deg, against the strongest)."""
    return {"sea": {"omega": sea.omega, "zeta": sea.zeta, "coherence": sea.coherence,
                    "equations": {model.state_names[i]: {"std": math.hypot(a, c),
                                                         "phase": math.degrees(math.atan2(c, a))}
                                  for i, a, c in sea.loading}}}


def _finding_dict(f: Finding) -> dict[str, Any]:
    out = {k: getattr(f, k) for k in ("effect", "target", "parameters", "std", "confidence",
                                      "explanation", "improvement")}
    if f.standard_form:
        out["standard_form"] = f.standard_form
    if f.withdrawn:
        out["withdrawn"] = f.withdrawn
    for key in ("fitted_range", "named_as", "between_records"):
        if getattr(f, key):
            out[key] = getattr(f, key)
    return out


def _plain(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"not JSON-serialisable: {type(value).__name__}")


def _with_unit(value: float, unit: str) -> str:
    """``value unit``, angles also in degrees."""
    text = f"{value:.4g} {unit}"
    if unit.startswith("rad"):
        text += f" ({math.degrees(value):.3g} deg{unit[3:]})"
    return text


def _fmt(value: Any) -> str:
    return f"{value:.4g}" if isinstance(value, float) else str(value)
