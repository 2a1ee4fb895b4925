"""The benchmark's statistics against rliable (Agarwal et al. 2021, the library the report
follows): the interquartile mean, the probability of improvement and the bootstrap intervals.

rliable does not install cleanly beside this stack (its bootstrap needs ``arch`` < 8, which fails
to import with pandas 3; arch 8 no longer takes rliable's ``random_state``), so it is not a test
dependency. The references below were computed with rliable 1.2.0 (``rliable.metrics``) and, for
the intervals, with arch 8.0's ``IIDBootstrap`` percentile interval, which is what rliable's
``StratifiedBootstrap`` runs for one task (50,000 resamples, seed 0). Where rliable's metrics
import, they are also compared live on random inputs.

IQM and probability of improvement are the same formulas, so they agree to rounding. The
intervals come from other random streams, so they agree to the bootstrap's own sampling error
(0.01 here): :func:`accd_gym.evals.sweep.bootstrap_interval` is rliable's one-task stratified
bootstrap, and :func:`accd_gym.evals.benchmark.stratified_bootstrap`, which also resamples each
seed's episodes, becomes it when the seeds have so many episodes that the episode level adds
nothing measurable."""

from __future__ import annotations

import numpy as np
import pytest

from accd_gym.evals.benchmark import iqm, probability_of_improvement, stratified_bootstrap
from accd_gym.evals.sweep import bootstrap_interval

#: (values, rliable.metrics.aggregate_iqm of them).
IQM_REFERENCES = [
    ([0.512], 0.512),
    ([0.943, 0.511, 0.976, 0.081], 0.727),
    ([0.805, 0.808, 0.515, 0.286, 0.054], 0.5353333333333333),
    ([0.956, 0.208, 0.828, 0.149, 0.513, 0.136, 0.689, 0.842, 0.426, 0.957], 0.5843333333333333),
    ([0.865, 0.855, 0.811, 0.261, 0.077, 0.946, 0.614, 0.003, 0.91, 0.985, 0.286, 0.814, 0.082], 0.6437142857142858),
]
#: Runs of X and Y and rliable.metrics.probability_of_improvement(X, Y) (ties count one half).
POI_X = [1.0, 0.75, 0.75, 0.5, 0.25]
POI_Y = [0.75, 0.5, 0.5, 1.0, 0.0, 0.25, 0.75]
POI_X_OVER_Y = 0.6
#: Per-seed rates and the 95 % percentile interval of their IQM (arch 8.0 IIDBootstrap, seed 0).
RATES = [0.706, 0.883, 0.804, 0.446, 0.495, 0.868, 0.303, 0.834, 0.818, 0.604, 0.497, 0.481]
RATES_INTERVAL = (0.49683333, 0.811)
SWEEP = [0.26, 0.366, 0.761, 0.608, 0.266, 0.503, 0.535, 0.312, 0.714, 0.28]
SWEEP_INTERVAL = (0.304, 0.60316667)


@pytest.mark.parametrize("values,expected", IQM_REFERENCES)
def test_iqm_is_rliables_on_its_references(values, expected):
    assert iqm(values) == pytest.approx(expected, rel=1e-12)


def test_probability_of_improvement_is_rliables_on_its_reference():
    assert probability_of_improvement(POI_X, POI_Y) == pytest.approx(POI_X_OVER_Y, abs=1e-12)
    assert probability_of_improvement(POI_Y, POI_X) == pytest.approx(1.0 - POI_X_OVER_Y, abs=1e-12)
    assert probability_of_improvement(POI_X, POI_X) == pytest.approx(0.5)  # rliable's value for equal runs


def test_the_stratified_bootstrap_interval_is_rliables_over_seeds():
    episodes = 200_000  # the episode-level resampling then moves a seed's rate by about 1e-3
    captured = [np.arange(episodes) < round(r * episodes) for r in RATES]
    lo, hi = stratified_bootstrap(captured)
    assert lo == pytest.approx(RATES_INTERVAL[0], abs=0.01) and hi == pytest.approx(RATES_INTERVAL[1], abs=0.01), (lo, hi)


def test_the_sweeps_bootstrap_interval_is_rliables():
    lo, hi = bootstrap_interval(SWEEP)
    assert lo == pytest.approx(SWEEP_INTERVAL[0], abs=0.01) and hi == pytest.approx(SWEEP_INTERVAL[1], abs=0.01), (lo, hi)


@pytest.mark.parametrize("seed", range(6))
def test_iqm_and_probability_of_improvement_match_rliable_live(seed):
    metrics = pytest.importorskip("rliable.metrics")
    rng = np.random.default_rng(seed)
    x = rng.uniform(0, 1, 3 + 4 * seed)
    assert iqm(x) == pytest.approx(metrics.aggregate_iqm(x.reshape(-1, 1)), rel=1e-12)
    a, b = rng.integers(0, 5, 5) / 4.0, rng.integers(0, 5, 7) / 4.0  # few values: many ties
    theirs = metrics.probability_of_improvement(a.reshape(-1, 1), b.reshape(-1, 1))
    assert probability_of_improvement(a, b) == pytest.approx(theirs, abs=1e-12)
