"""The batch loop's cheaper paths against single runs: command latency with odometry every
step (a gather per step), a full A_tau (velocity terms and offsets), the block-wise
metrics and the heading carried by angle addition across the +-pi wrap."""
from __future__ import annotations

import math

import numpy as np
import pytest

from batch_checks import assert_metrics_equal, gain, perturbations, single_runs, trace_deviation
from nonfragile_tracker.control.simulation.batch import BatchCases, simulate_batch
from nonfragile_tracker.control.simulation.plant import PlantConfig
from nonfragile_tracker.control.simulation.tracker import TrackerConfig
from nonfragile_tracker.control.simulation.reference import circle, figure_eight
from nonfragile_tracker.interface.scenario import paper_plant_config


def check_against_single_runs(plant, tracker, path, steps, cases, exact, steady_from=None):
    """Worst |batch - single run| over the logged fields; every metric within 1e-12."""
    br = simulate_batch(plant, tracker, path, steps, cases, record=True, exact=exact,
                        steady_from=steady_from)
    worst = 0.0
    for i, run in single_runs(plant, tracker, path, steps, cases):
        worst = max(worst, trace_deviation(run, br, i))
        assert_metrics_equal(run, br, i, first_within=True)
    return worst


@pytest.mark.parametrize('exact', [True, False])
def test_command_latency_with_odometry_every_step_equals_single_runs(exact):
    """Per-case command latencies (0 to 0.3 s) and lags on the paper plant, headings
    started next to +-pi (the wrap), a run length that is no whole number of metric blocks
    and a steady window starting inside one."""
    rng = np.random.default_rng(11)
    n = 6
    pc = paper_plant_config()
    cases = BatchCases(n, perturbation=perturbations(rng, n),
                       cmd_latency=[0.0, 0.01, 0.13, 0.3, 0.2, 0.05],
                       lag_v=[0.0, 0.0, 0.05, 0.0, 0.1, 0.0], lag_w=[0.0, 0.0, 0.0, 0.05, 0.1, 0.0],
                       x0=0.7 + rng.uniform(-0.2, 0.2, n),
                       th0=[3.14, -3.14, math.pi, -3.0, 2.9, 0.5])
    worst = check_against_single_runs(pc, TrackerConfig(K=gain()), circle(), 1007, cases,
                                      exact, steady_from=3.333)
    assert worst < 1e-12
    if exact:
        assert worst == 0.0


@pytest.mark.parametrize('exact', [True, False])
@pytest.mark.parametrize('tau', [0.0, 0.05])
def test_full_state_delay_matrix_equals_single_runs(exact, tau):
    """A_tau with every entry nonzero (delayed velocities, the velocity offset), with and
    without a delay, command latency on some cases, a figure eight."""
    rng = np.random.default_rng(12)
    n = 4
    A_tau = (0.05 * rng.standard_normal((4, 4))).tolist()
    pc = PlantConfig(dt=0.01, tau=tau, A_tau=A_tau, x0=0.1, y0=-0.2, th0=0.3, v0=0.1)
    cases = BatchCases(n, perturbation=perturbations(rng, n), cmd_latency=[0.0, 0.02, 0.0, 0.1],
                       th0=rng.uniform(-3.0, 3.0, n))
    path = figure_eight(radius=1.0, rate=0.2)
    worst = check_against_single_runs(pc, TrackerConfig(K=gain()), path, 900, cases, exact)
    assert worst < 1e-12
    if exact:
        assert worst == 0.0


def test_cheaper_forms_agree_with_exact_on_a_large_batch():
    """300 cases of the paper scenario: the cheaper forms (heading by angle addition,
    squared-error metrics) against the exact mode, which equals single runs bit for bit."""
    rng = np.random.default_rng(13)
    n = 300
    pc = paper_plant_config()
    cases = BatchCases(n, perturbation=perturbations(rng, n),
                       x0=0.7 + rng.uniform(-0.3, 0.3, n), th0=rng.uniform(-math.pi, math.pi, n),
                       cmd_latency=rng.integers(0, 30, n) * 0.01)
    tc = TrackerConfig(K=gain())
    a = simulate_batch(pc, tc, circle(), 2000, cases, exact=True)
    b = simulate_batch(pc, tc, circle(), 2000, cases, exact=False)
    for name in ('final_error', 'rms_error', 'steady_error', 'peak_abs_v', 'peak_abs_w'):
        assert np.max(np.abs(getattr(a, name) - getattr(b, name))) < 1e-12
    assert np.array_equal(a.settling_time, b.settling_time, equal_nan=True)
    assert np.array_equal(a.first_within, b.first_within, equal_nan=True)
    assert a.finite.all() and b.finite.all()
