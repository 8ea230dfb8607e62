"""Mismatch diagnosis: why a simulation and a recording disagree.

:func:`diagnose` locates the mismatch (channels, windows, band), names the physics the model left
out as catalogue entries (:mod:`marine_envs.effects`), fits them with uncertainty and shows the
improvement on held-out data. Layers: :mod:`.residuals` (nominal smoother, equation errors),
:mod:`.hypotheses` (every catalogue entry fitted to them), :mod:`.rollout` (multi-step
predictions), :mod:`.diagnosis` (validated greedy selection), :mod:`.api`, :mod:`.report`.
"""

from .api import Diagnosis, Finding, check, diagnose
from .diagnosis import DiagnosisConfig

__all__ = ["Diagnosis", "DiagnosisConfig", "Finding", "check", "diagnose"]
