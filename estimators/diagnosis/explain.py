"""Findings in words: what each fitted effect means for the vehicle, with its numbers."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from marine_envs.models.effects import Effect

from .residuals import Residuals


def explain(effect: Effect, scored: Any, residuals: Residuals) -> str:
    """One or two sentences a marine engineer can act on."""
    share = f"it removes {scored.alone:.0%} of the held-out prediction error beyond sensor noise"
    if getattr(scored, "on_innovations", False):  # an actuator effect, an unmeasured state
        share = (f"it removes {scored.innovation_gain:.1%} of the held-out one-step innovations "
                 f"(its few-second predictions: {scored.alone:+.0%})")
    if effect.effect == "parameter_change":
        return f"{describe_change(effect, scored.fitted.std, scored.fitted.details)}; {share}."
    return f"{describe(effect)}; {share}."


def describe_change(effect: Effect, std: Mapping[str, float], details: Mapping[str, Any]) -> str:
    """A change in mid-record: when (with the std of its date), which equation, what changed
    and by how much, before and after (the level before is the detector's
    :class:`.changes.ChangePoint` in ``details["change"]``, when there is one)."""
    p, t = effect.parameters, effect.target
    spread = std.get("time")
    when = f"t = {p['time']:.1f} s" + (f" (+- {spread:.{1 if spread < 10 else 0}f} s)"
                                       if spread else "")
    c, c_std = p["c"], std.get("c")
    size = f"{c:+.3g}" + (f" +- {c_std:.2g}" if c_std else "")
    change = details.get("change")
    if p.get("what", "damping") == "force":
        return (f"the forces on {t} change at {when}: from then on {t}'s equation needs a "
                f"constant {size} per second" + (
                    f" (its mean error goes from {change.before:+.3g} to "
                    f"{change.before + c:+.3g})"
                    if change is not None else ""))
    text = (f"the damping of {t} changes at {when}: from then on {t}'s equation needs "
            f"{size}*{t} ({'more' if c < 0 else 'less'} damping than before: a drag, mass or "
            "added-mass change)")
    if change is not None and change.before:
        text += (f"; its damping derivative d({t}')/d{t} goes from {change.before:+.3g} to "
                 f"{change.before + c:+.3g} 1/s ({c / change.before:+.0%})")
    return text


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
    if effect.effect == "parameter_change":
        return describe_change(effect, {}, {})
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
