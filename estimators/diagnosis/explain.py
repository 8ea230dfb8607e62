"""Findings in words: what each fitted effect means for the vehicle, with its numbers."""

from __future__ import annotations

from typing import Any

from marine_envs.models.effects import Effect

from .residuals import Residuals


def explain(effect: Effect, scored: Any, residuals: Residuals) -> str:
    """One or two sentences a marine engineer can act on."""
    share = f"it removes {scored.alone:.0%} of the held-out prediction error beyond sensor noise"
    if getattr(scored, "on_innovations", False):  # an actuator effect, an unmeasured state
        share = (f"it removes {scored.innovation_gain:.1%} of the held-out one-step innovations "
                 f"(its few-second predictions: {scored.alone:+.0%})")
    return f"{describe(effect)}{_dating(effect, scored)}; {share}."


def _dating(effect: Effect, scored: Any) -> str:
    """How closely the record dates a change (the 68 % interval of its time's posterior)."""
    spread = scored.fitted.std.get("time", 0.0) if effect.effect == "parameter_change" else 0.0
    return f" (give or take {spread:.0f} s: the record cannot date it closer)" \
        if spread >= 1.0 else ""


_DAMPING = {"linear_damping", "quadratic_damping", "nonlinear_damping"}


def separating_test(a: Effect, b: Effect) -> str:
    """A test that would tell two terms apart that one record cannot."""
    kinds = {a.effect, b.effect}
    if kinds <= _DAMPING:
        return (f"a test at a larger amplitude of {a.target}: x, x|x| and x^3 damping agree over "
                "the amplitudes recorded and part beyond them")
    if "sensor_bias" in kinds or "current" in kinds:
        return "a record with another mean: a sensor offset stays, a steady force changes it"
    if "parameter_change" in kinds:
        return ("a second record: a change happens once, at a time; a missing term acts "
                "whenever its state is excited")
    if any(k.startswith("input_") for k in kinds):
        return ("steps of the input of several sizes and rates: an actuator effect shapes "
                "what the vessel receives, a hull term how it responds")
    return "a test that excites the two terms differently (another amplitude or input)"


def describe(effect: Effect) -> str:
    """What the effect means for the vehicle, with its numbers."""
    p, t = effect.parameters, effect.target
    return {
        "current": f"a steady force or current the model lacks: {t}'s equation needs a constant "
                   f"{p.get('b', 0):+.3g} per second",
        "linear_damping": f"the linear damping of {t} is wrong: {t}'s equation needs "
                          f"{p.get('c', 0):+.3g}*{t} ({'more' if p.get('c', 0) < 0 else 'less'}"
                          " damping than modelled)",
        "quadratic_damping": (f"{t} decays faster at large |{t}| than the linear model allows: "
                              f"a drag {p.get('c', 0):+.3g}*{t}*|{t}| (quadratic, viscous/"
                              "eddy-making)") if p.get("c", 0) <= 0 else
                             (f"{t} decays slower at large |{t}| than the linear model allows: "
                              f"{p.get('c', 0):+.3g}*{t}*|{t}| (less damping with amplitude)"),
        "nonlinear_damping": (f"damping of {t} grows with amplitude faster than x|x|: "
                              f"{p.get('c', 0):+.3g}*{t}^3") if p.get("c", 0) <= 0 else
                             (f"damping of {t} falls with amplitude: "
                              f"{p.get('c', 0):+.3g}*{t}^3"),
        "coupling": f"{p.get('source')} drives {t} in a way the model omits: "
                    f"{p.get('c', 0):+.3g}*{p.get('source')} in {t}'s equation",
        "nonlinear_restoring": f"the restoring force on {t} is not linear in "
                               f"{p.get('source')}: {p.get('c', 0):+.3g}*{p.get('source')}^3 "
                               f"({'stiffening' if p.get('c', 0) < 0 else 'softening'})",
        "parameter_change": f"the dynamics of {t} change at t = {p.get('time', 0):.1f} s: from "
                            f"then on its {p.get('what', 'damping')} changes by "
                            f"{p.get('c', 0):+.3g}",
        "wave_frequency": f"an oscillation the model does not have drives {t}: narrow-band at "
                          f"{p.get('omega', 0):.3g} rad/s (period "
                          f"{6.283 / max(p.get('omega', 1e-9), 1e-9):.3g} s), damping ratio "
                          f"{p.get('zeta', 0):.2g}",
        "unlisted": f"no catalogue entry fits; a sparse regression finds {p.get('c', 0):+.3g}*"
                    f"{p.get('expression')} in {t}'s equation",
        "input_gain": f"the actuator {t} is {'weaker' if p.get('k', 1) < 1 else 'stronger'} "
                      f"than modelled: applied = {p.get('k', 1):.3g} x commanded",
        "input_delay": f"the actuator {t} responds {p.get('tau', 0):.2g} s late (transport "
                       "delay)",
        "input_saturation": f"the actuator {t} saturates at +-{p.get('limit', 0):.3g} (about "
                            "its nominal value)",
        "input_deadzone": f"the actuator {t} ignores commands smaller than "
                          f"{p.get('width', 0):.3g} (dead zone)",
        "input_rate_limit": f"the actuator {t} cannot move faster than {p.get('rate', 0):.3g} "
                            "per second (rate limit)",
        "sensor_bias": f"the {t} sensor reads {p.get('b', 0):+.3g} off (constant bias): the "
                       "other channels contradict it",
    }[effect.effect]
