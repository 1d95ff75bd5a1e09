"""The batch plant's fast step (``VectorPlant._advance_fast``: odometry of the plant's own
state at every step, no actuator dynamics, ``exact=False``) against single runs and against
the exact mode: with and without the paper's state delay, with command latencies, per-case
analytic paths, speeds starting below ``min_speed`` and switching perturbations."""
from __future__ import annotations

import math

import numpy as np
import pytest

from batch_checks import (FIELDS, assert_metrics_equal, gain, perturbations, single_runs,
                          trace_deviation)
from nonfragile_tracker.control.simulation.batch import BatchCases, PathBatch, simulate_batch
from nonfragile_tracker.control.simulation.plant import PlantConfig, VectorPlant
from nonfragile_tracker.control.simulation.tracker import TrackerConfig
from nonfragile_tracker.control.simulation.reference import circle
from nonfragile_tracker.interface.scenario import paper_plant_config


@pytest.fixture
def ideal_calls(monkeypatch):
    """Counts the runs whose plant took the fast step (one entry per run)."""
    calls = []
    inner = VectorPlant._advance_fast

    def spy(self, k, *args):
        if k == 0:
            calls.append(1)
        return inner(self, k, *args)

    monkeypatch.setattr(VectorPlant, '_advance_fast', spy)
    return calls


def worst_against_single_runs(plant, tracker, path, steps, cases):
    """Worst |batch - single run| over the logged fields; metrics within 1e-12, with and
    without a trace (without, the heading advances once per metrics block)."""
    br = simulate_batch(plant, tracker, path, steps, cases, record=True, exact=False)
    bn = simulate_batch(plant, tracker, path, steps, cases, exact=False)
    worst = 0.0
    for i, run in single_runs(plant, tracker, path, steps, cases):
        worst = max(worst, trace_deviation(run, br, i))
        for b in (br, bn):
            assert_metrics_equal(run, b, i)
    assert bn.finite.all()
    return worst


def test_paper_delay_latencies_and_slow_starts_equal_single_runs(ideal_calls):
    """The paper plant (d = (a x, b y)(t - tau)), command latencies 0-0.3 s, initial speeds
    0, -0 and below min_speed (the guarded division), headings next to +-pi (the wrap)."""
    rng = np.random.default_rng(21)
    n = 6
    cases = BatchCases(n, perturbation=perturbations(rng, n),
                       cmd_latency=[0.0, 0.0, 0.07, 0.3, 0.01, 0.15],
                       v0=[0.0, 0.0005, 0.05, -0.0002, 0.2, -0.0],
                       x0=0.7 + rng.uniform(-0.2, 0.2, n),
                       th0=[3.14, -3.14, math.pi, -3.0, 0.5, 2.0])
    worst = worst_against_single_runs(paper_plant_config(),
                                      TrackerConfig(K=gain()),
                                      circle(), 1203, cases)
    assert worst < 1e-12
    assert ideal_calls == [1, 1]


def test_no_state_delay_and_per_case_paths_equal_single_runs(ideal_calls):
    """A_tau = 0 (no delay ring), per-case figure-eight parameters, no latency."""
    rng = np.random.default_rng(22)
    n = 4
    pc = PlantConfig(dt=0.01, x0=0.1, y0=-0.2, th0=0.3, v0=0.1)
    cases = BatchCases(n, perturbation=perturbations(rng, n), th0=rng.uniform(-3.0, 3.0, n))
    path = PathBatch('figure_eight', radius=rng.uniform(0.5, 1.5, n),
                     rate=rng.uniform(0.1, 0.3, n), phase=rng.uniform(0, 1, n))
    worst = worst_against_single_runs(
        pc, TrackerConfig(K=gain()), path, 900, cases)
    assert worst < 1e-12
    assert ideal_calls == [1, 1]


def test_switching_perturbation_agrees_with_the_exact_mode(ideal_calls):
    """Random time-varying Delta (5 segments of 0.5 s) on 40 cases with latencies: the
    fast step against the exact mode (a single run's operations, bit for bit)."""
    rng = np.random.default_rng(23)
    n = 40
    cases = BatchCases(n, perturbation=perturbations(rng, n, 5), hold=0.5,
                       cmd_latency=rng.integers(0, 20, n) * 0.01,
                       x0=0.7 + rng.uniform(-0.3, 0.3, n), th0=rng.uniform(-math.pi, math.pi, n))
    pc = paper_plant_config()
    tc = TrackerConfig(K=gain())
    a = simulate_batch(pc, tc, circle(), 1500, cases, exact=True, record=True)
    b = simulate_batch(pc, tc, circle(), 1500, cases, exact=False, record=True)
    assert ideal_calls == [1]
    for name in FIELDS:
        assert np.max(np.abs(a.trace[name] - b.trace[name])) < 1e-12
    for name in ('final_error', 'rms_error', 'steady_error', 'peak_abs_v', 'peak_abs_w'):
        assert np.max(np.abs(getattr(a, name) - getattr(b, name))) < 1e-12
    assert np.array_equal(a.settling_time, b.settling_time, equal_nan=True)
    assert b.finite.all()
