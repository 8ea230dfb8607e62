"""The diagnosis on the tuned part of its seeded acceptance set (issue 6), as a regression guard:
every catalogue effect once, on the USV and the hovercraft in turn and at 5 % and 10 % sensor
noise in turn, one pair per vehicle and one effect-free record per vehicle and noise, seed 0
(``TUNED_VEHICLES``). The whole tuned set (every effect on both vehicles at both noises, seeds
0 and 1), the held-out seeds and the other three vehicles are measured by
``benchmarks/diagnosis.py``, not here: too long for CI.

The rates are held at floors: what the method reaches today, a little below, so that a change
that makes it worse fails here. The acceptance targets themselves
(``estimators.diagnosis.cases.ACCEPTANCE``) are reported by ``benchmarks/diagnosis.py``; raise
the floors towards them as the method improves. About 5 min on 2 cores.
"""

import os
from concurrent.futures import ProcessPoolExecutor

import pytest

from estimators.diagnosis.cases import (
    EFFECT_FREE_SEED,
    TARGETS,
    TUNED_VEHICLES,
    Case,
    catalogue_cases,
    confusion,
    run_case,
    summarize,
)

NOISES = (0.05, 0.10)

#: Floors under the rates measured on this set (2026-11-29: ranked right and held-out improvement
#: 17/17, right and key parameter 16/17, effect-free records clean 4/4): about one more miss each.
FLOORS = {"right": 0.88, "ranked_right": 0.94, "parameter_ok": 0.88, "improvement_ok": 0.94,
          "clean": 0.75}


def alternating_cases() -> list[Case]:
    """Catalogue entry k on vehicle k mod 2 at noise (k // 2) mod 2, so each effect runs once
    and each vehicle sees both noises; pair v of vehicle v at the other noise; one effect-free
    record per vehicle and noise, each on its own seed."""
    cases = []
    for v, model in enumerate(TUNED_VEHICLES):
        for n, noise in enumerate(NOISES):
            *groups, effect_free = catalogue_cases((model,), noises=(noise,), effect_free=1,
                                                   effect_free_seed=EFFECT_FREE_SEED + n)
            singles, pairs = groups[:len(TARGETS[model])], groups[len(TARGETS[model]):]
            cases += [c for k, c in enumerate(singles) if k % 2 == v and (k // 2) % 2 == n]
            cases += ([pairs[v]] if n != v else []) + [effect_free]
    return cases


@pytest.fixture(scope="module")
def outcomes():
    with ProcessPoolExecutor(min(2, os.cpu_count() or 1)) as pool:
        return list(pool.map(run_case, alternating_cases()))


def test_the_set_covers_every_effect_on_two_vehicles_and_both_noises(outcomes):
    assert len({o.model for o in outcomes}) >= 2
    assert {o.case.split("/")[2] for o in outcomes} == {"noise=0.05", "noise=0.10"}
    assert {t.split(":")[0] for o in outcomes for t in o.true} == {
        e for entries in TARGETS.values() for e, _, _ in entries}
    assert sum(not o.true for o in outcomes) == 2 * len(NOISES)
    assert not [o.case for o in outcomes if o.reason.startswith("crashed")]


@pytest.mark.parametrize("check", sorted(FLOORS))
def test_acceptance_rates_hold_their_floors(outcomes, check):
    rates = summarize(outcomes)
    assert rates[check]["rate"] >= FLOORS[check], (
        f"{check}: {rates[check]['rate']:.2f} < floor {FLOORS[check]}\n{confusion(outcomes)}")
