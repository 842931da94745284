"""The level rules tried for the re-levelled -40 kgf Cranfield current (issue 35; docs/diagnose.md,
"Can the re-levelled -40 kgf current be detected?"): their statistics on synthetic currents with known
answers, and the figures the docs give on the development set (none of the rules separates the -40 kgf
rows from the +20/+40 kgf ones, which is why none is shipped). The Cranfield part (slow, about
2.5 s) reads ../shared/data/cranfield-actuator and skips with the reason where absent.
"""

from __future__ import annotations

import numpy as np
import pytest
from bench import bench_diagnose_cranfield_relevel as rl
from scipy import stats

from support import cranfield

WIN = {"extension": (40, 120), "dwell": (164, 195), "retraction": (239, 320)}
LEVEL = np.r_[np.full(124, 0.75), np.full(75, 0.40), np.full(125, 0.96)]  # A, one cycle's segment levels
SEGMENTS = ((0, 124), (124, 199), (199, 324))


def _honest(seed: int, runs: int = 10, cycles: int = 5, noise_A: float = 0.04) -> list:
    rng = np.random.default_rng(seed)
    return [LEVEL + noise_A * rng.standard_normal((cycles, rl.CYCLE)) for _ in range(runs)]


def _relevelled(runs: list) -> list:
    """Each cycle's segment shifted so that its mean over the steady window is the nominal level."""
    out = []
    for c in runs:
        c = c.copy()
        for a, b in WIN.values():
            lo, hi = next(s for s in SEGMENTS if s[0] <= a < s[1])
            c[:, lo:hi] += LEVEL[a] - c[:, a:b].mean(1, keepdims=True)
        out.append(c)
    return out


def _forced(runs: list) -> list:
    """Each run's steady windows shifted so that their mean over the run is the nominal level."""
    out = []
    for c in runs:
        c = c.copy()
        for a, b in WIN.values():
            c[:, a:b] += LEVEL[a] - c[:, a:b].mean()
        out.append(c)
    return out


def test_the_pair_rule_flags_imposed_levels_and_not_independent_recordings():
    assert stats.norm.cdf(rl.C_PAIR) - stats.norm.cdf(-rl.C_PAIR) == pytest.approx(rl.ALPHA ** (1 / 3))
    honest = rl.pair_z((_honest(1), WIN), (_honest(2), WIN))
    imposed = rl.pair_z((_forced(_honest(1)), WIN), (_forced(_honest(2)), WIN))
    assert all(abs(imposed[k]["z"]) < 1e-6 for k in rl.KINDS)
    assert not all(abs(honest[k]["z"]) < rl.C_PAIR for k in rl.KINDS)


def test_the_cycle_rule_sees_under_dispersion_of_a_relevelled_current_only():
    honest = rl.under_dispersion((_honest(3), WIN))
    relevelled = rl.under_dispersion((_relevelled(_honest(3)), WIN))
    for k in rl.KINDS:
        assert honest[k]["p_under"] > rl.P_UNDER
        assert relevelled[k]["F"] < 0.1 and relevelled[k]["p_under"] < rl.P_UNDER  # not 0: blocks != window


def test_the_run_rule_sees_under_dispersion_of_runs_forced_to_one_level_and_not_of_drifting_runs():
    runs = _honest(4)
    drift = [c + 0.01 * i for i, c in enumerate(runs)]  # 10 mA a session, as sessions drift
    assert rl.run_dispersion((drift, WIN))["p_under"] > 0.5
    assert rl.run_dispersion((_forced(runs), WIN))["p_under"] < rl.P_UNDER


@pytest.fixture(scope="module")
def rows():
    cranfield.require()
    return rl.table()


@pytest.mark.slow
def test_on_cranfield_no_rule_separates_the_relevelled_rows_as_the_docs_say(rows):
    minus = [r for r in rows if r["load_kgf"] < 0]
    plus = [r for r in rows if r["load_kgf"] > 0]
    assert len(minus) == 7 and len(plus) == 14
    counts = {rule: (sum(r[f"flag_{rule}"] for r in minus), sum(r[f"flag_{rule}"] for r in plus))
              for rule in "abc"}
    assert counts == {"a": (0, 0), "b": (0, 4), "c": (2, 0)}
