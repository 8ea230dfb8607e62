"""The description of a vessel an environment simulates: which vehicle, its model parameters and
the catalogue effects its nominal model leaves out (:mod:`marine_envs.models.effects`).

The schema, one JSON object (SI units, the parameters by docs/models.md symbol)::

    {"vehicle": "usv",
     "params": {"wn": 2.4628, "zeta": 0.0038},
     "effects": [{"effect": "nonlinear_restoring", "target": "p",
                  "parameters": {"source": "phi", "c": -3.94}}],
     "left_out": ["wave_frequency on p: its forcing is a process of its own, ..."]}

``vehicle`` is a model name (:func:`marine_envs.models.model_names`); ``params`` overrides its
nominal parameters; ``effects`` are the effects an environment adds to it; ``left_out``
(optional, informational) says what a diagnosis found that an environment cannot carry. A
diagnosis JSON holds its vessel in this schema as its ``"environment"`` block, so
``gym.make(ENV_ID, effects="diagnosis.json")`` is the diagnosed vessel: its parameters and its
effects, refused when the diagnosis is of another vehicle (:func:`read_vessel`).
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .files import write_text
from .models import VehicleModel, get_model, model_names
from .models.effects import REQUIRED, Effect

#: The keys of the schema; ``left_out`` may be missing.
KEYS = ("vehicle", "params", "effects", "left_out")
#: The keys of one entry of ``effects``.
EFFECT_KEYS = ("effect", "target", "parameters")
#: State effects an environment cannot carry as a fixed part of its model, and why.
NOT_CARRIED = {
    "wave_frequency": "its forcing is a narrow-band process of its own, not a term of the model",
    "parameter_change": "it switches on at a time of the record, not a term of the model",
}


@dataclass(frozen=True)
class VesselDescription:
    """A vessel as an environment simulates it (the module's schema), validated on creation.

    :param vehicle: model name, or None for effects alone (a list given to ``effects=``: they
        fit any vehicle whose names they use, checked when the environment adds them).
    :param params: nominal parameter overrides by docs/models.md symbol, SI units.
    :param effects: catalogue effects the environment adds.
    :param left_out: what the source found that an environment cannot carry, one line each.
    :raises ValueError: an unknown vehicle or parameter, a value out of its range, or an effect
        the vehicle cannot carry, naming it.
    """

    vehicle: str | None
    params: Mapping[str, Any] = field(default_factory=dict)
    effects: tuple[Effect, ...] = ()
    left_out: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "params", dict(self.params))
        object.__setattr__(self, "effects", tuple(self.effects))
        object.__setattr__(self, "left_out", tuple(self.left_out))
        if self.vehicle is None:
            if self.params:
                raise ValueError("a vessel's params need its vehicle (the model they belong to)")
            return
        model = self.model()
        for k, effect in enumerate(self.effects):
            reason = not_carried(effect, model)
            if reason:
                raise ValueError(f"effects[{k}] ({effect.effect} on {effect.target}): {reason}")

    def model(self) -> VehicleModel:
        """The vehicle's model with :attr:`params` (no effects).

        :raises ValueError: an unknown vehicle, an unknown parameter or a value out of range.
        """
        if self.vehicle not in model_names():
            raise ValueError(f"unknown vehicle {self.vehicle!r}; available: "
                             f"{', '.join(model_names())}")
        nominal = get_model(self.vehicle)
        nominal.check_parameter_names(self.params)
        for name, value in self.params.items():
            if isinstance(getattr(nominal.params, name), float) and (
                    isinstance(value, bool) or not isinstance(value, int | float)):
                raise ValueError(f"params of vehicle {self.vehicle!r}: {name}={value!r} must "
                                 "be a number")
        try:
            return nominal.with_params(**self.params)
        except (TypeError, ValueError) as error:
            raise ValueError(f"params of vehicle {self.vehicle!r}: {error}") from None

    def check_vehicle(self, vehicle: str, environment: str) -> None:
        """Check that ``environment``, which simulates ``vehicle``, may take this vessel.

        :raises ValueError: the description is of another vehicle (naming both).
        """
        if self.vehicle is not None and self.vehicle != vehicle:
            raise ValueError(f"effects describe a vessel of vehicle {self.vehicle!r}; "
                             f"{environment} simulates vehicle {vehicle!r}")

    def environment_params(self, given: Mapping[str, Any] | None) -> dict[str, Any]:
        """The ``params=`` of an environment of this vessel: :attr:`params`, overridden by the
        ones ``given`` to the environment itself."""
        return {**self.params, **(given or {})}

    def to_dict(self) -> dict[str, Any]:
        """The schema's JSON object.

        :raises ValueError: a description without a vehicle.
        """
        if self.vehicle is None:
            raise ValueError("a vessel description needs its vehicle to be written")
        out: dict[str, Any] = {"vehicle": self.vehicle, "params": dict(self.params),
                               "effects": [e.to_dict() for e in self.effects]}
        if self.left_out:
            out["left_out"] = list(self.left_out)
        return out

    def to_json(self, path: str | Path | None = None) -> str:
        """The JSON text, written to ``path`` when given (whole or not at all)."""
        text = json.dumps(self.to_dict(), indent=2)
        if path is not None:
            write_text(path, text + "\n")
        return text

    @classmethod
    def from_dict(cls, document: Any, where: str = "the vessel description") -> VesselDescription:
        """A description from its JSON object.

        :raises ValueError: a malformed one, naming ``where`` and the offending key, parameter
            or effect.
        """
        try:
            if not isinstance(document, Mapping):
                raise ValueError(f"a JSON object {{{', '.join(KEYS[:3])}}} expected, not "
                                 f"{type(document).__name__}")
            unknown = sorted(set(document) - set(KEYS))
            if unknown:
                raise ValueError(f"unknown key(s) {unknown}; the schema has {', '.join(KEYS)}")
            if not isinstance(document.get("vehicle"), str):
                raise ValueError(f"'vehicle' must be a model name ({', '.join(model_names())})")
            params = document.get("params", {})
            if not isinstance(params, Mapping):
                raise ValueError("'params' must be an object {symbol: value}")
            left_out = document.get("left_out", [])
            if not (isinstance(left_out, list) and all(isinstance(s, str) for s in left_out)):
                raise ValueError("'left_out' must be a list of strings")
            effects = _schema_effects(document.get("effects", []))
            return cls(document["vehicle"], params, effects, tuple(left_out))
        except ValueError as error:
            raise ValueError(f"{where}: {error}") from None

    @classmethod
    def carrying(cls, vehicle: str, params: Mapping[str, Any],
                 effects: Sequence[Effect]) -> VesselDescription:
        """The description of ``vehicle`` with ``params`` and those of ``effects`` an
        environment can carry; the others go to :attr:`left_out` with the reason."""
        model = cls(vehicle, params).model()
        kept, left_out = [], []
        for effect in effects:
            reason = not_carried(effect, model)
            if reason:
                left_out.append(f"{effect.effect} on {effect.target}: {reason}")
            else:
                kept.append(effect)
        return cls(vehicle, params, tuple(kept), tuple(left_out))


def not_carried(effect: Effect, model: VehicleModel) -> str:
    """Why an environment of ``model`` cannot carry ``effect``, or ``""`` when it can."""
    if effect.effect in NOT_CARRIED:
        return NOT_CARRIED[effect.effect]
    try:
        effect.check(model)
    except ValueError as error:
        return str(error)
    return ""


def _schema_effects(entries: Any) -> tuple[Effect, ...]:
    """The ``effects`` list of the schema, each entry exactly :data:`EFFECT_KEYS`."""
    if not isinstance(entries, list):
        raise ValueError("'effects' must be a list of {effect, target, parameters}")
    out = []
    for k, entry in enumerate(entries):
        if not (isinstance(entry, Mapping) and {"effect", "target"} <= set(entry)
                and set(entry) <= set(EFFECT_KEYS)):
            raise ValueError(f"effects[{k}]: {entry!r} is not "
                             "{'effect', 'target', 'parameters'}")
        if not isinstance(entry.get("parameters", {}), Mapping):
            raise ValueError(f"effects[{k}]: 'parameters' must be an object")
        try:
            out.append(Effect(entry["effect"], entry["target"], entry.get("parameters", {})))
        except ValueError as error:
            raise ValueError(f"effects[{k}]: {error}") from None
    return tuple(out)


# -- reading what an environment's effects= gives ------------------------------------------------
def read_vessel(source: Any) -> VesselDescription:
    """The vessel ``effects=`` describes: a :class:`VesselDescription`, its JSON object, the
    path of a JSON file holding one (a description, or a diagnosis JSON's ``"environment"``
    block), or a sequence of effects (:func:`read_effects`; no vehicle, no parameters).

    A diagnosis JSON written before the block existed gives its ``model``, its ``params``
    overridden by the calibrated ones (refitted with the findings when there are) and its
    ``findings``, as the block would.

    :raises ValueError: a file that cannot be read or is neither, or a malformed description.
    """
    if isinstance(source, VesselDescription):
        return source
    if isinstance(source, str | Path):
        return _read_file(Path(source))
    if isinstance(source, Mapping) and "vehicle" in source:
        return VesselDescription.from_dict(source)
    return VesselDescription(None, {}, tuple(read_effects(source)))


def _read_file(path: Path) -> VesselDescription:
    try:
        document = json.loads(path.read_text())
    except OSError as error:
        raise ValueError(f"effects {path}: cannot read it: {error.strerror or error}") from None
    except json.JSONDecodeError as error:
        raise ValueError(f"effects {path}: not a JSON file: {error}") from None
    if isinstance(document, Mapping) and "vehicle" in document:
        return VesselDescription.from_dict(document, f"effects {path}")
    if isinstance(document, Mapping) and isinstance(document.get("environment"), Mapping):
        return VesselDescription.from_dict(document["environment"],
                                           f"effects {path}: its 'environment'")
    if not (isinstance(document, Mapping) and "findings" in document):
        raise ValueError(f"effects {path}: not a diagnosis JSON nor a vessel description (no "
                         "'findings', no 'vehicle')")
    return _older_diagnosis(document, f"effects {path}")


def _older_diagnosis(document: Mapping[str, Any], where: str) -> VesselDescription:
    """The vessel of a diagnosis JSON without an ``"environment"`` block (written before it
    existed): the rule the block follows (``estimators.diagnosis.result.Diagnosis``)."""
    try:
        refitted = {name: q["value"] for name, q in document.get("calibration_quality", {})
                    .get("with_findings", {}).items()}
        params = {**document.get("params", {}), **document.get("calibration", {}), **refitted}
        effects = read_effects(document["findings"])
        return VesselDescription.carrying(str(document.get("model")), params, effects)
    except (AttributeError, KeyError, TypeError, ValueError) as error:
        raise ValueError(f"{where}: a diagnosis JSON without an 'environment' block, and its "
                         f"model, params and findings do not describe a vessel: {error} "
                         "(diagnose again to write the block)") from None


def read_effects(effects: Any) -> list[Effect]:
    """Effects from :class:`~marine_envs.models.effects.Effect` objects, their ``to_dict()``
    forms (a finding's too: its companion terms ``with_EFFECT`` become effects of their own, on
    the same target and source), or the path of a diagnosis JSON or a vessel description (its
    effects: :func:`read_vessel`).

    :raises ValueError: a file that is neither, or an entry that is not an effect.
    """
    if isinstance(effects, str | Path):
        return list(_read_file(Path(effects)).effects)
    out = []
    for entry in effects:
        if isinstance(entry, Effect):
            out.append(entry)
        elif isinstance(entry, Mapping) and {"effect", "target"} <= set(entry):
            out += _with_companions(entry)
        else:
            raise ValueError(f"effects: {entry!r} is not an Effect or "
                             "{'effect', 'target', 'parameters'}")
    return out


def _with_companions(entry: Mapping[str, Any]) -> list[Effect]:
    """A finding's effect and its companions (``with_linear_damping``, ``with_coupling``: the
    linear term fitted beside it, on its target and, for a coupling, its source)."""
    parameters = dict(entry.get("parameters", {}))
    companions = {k[len("with_"):]: parameters.pop(k) for k in list(parameters)
                  if k.startswith("with_")}
    source = {"source": parameters["source"]} if "source" in parameters else {}
    return [Effect(entry["effect"], entry["target"], parameters),
            *(Effect(name, entry["target"],
                     {**(source if "source" in REQUIRED.get(name, ()) else {}), "c": value})
              for name, value in companions.items())]
