"""The identified static gains carry 95 % intervals (block bootstrap, as the latency's and
the lags'): a kinematic base whose turn rate is a known fraction of its command is identified
with an interval that holds that fraction, and the gain a base reaches in full with one that
holds 1.  The MuJoCo skid-steer's is in test_physics.py."""
from __future__ import annotations

import functools

import numpy as np
import pytest

from nonfragile_tracker.control.identification.identify import (
    CommandSamples, OdometrySamples, identify_latency)
from nonfragile_tracker.control.simulation.plant import PlantConfig, UnicyclePlant
from nonfragile_tracker.control.simulation.timing import step_time


def _recording(turn_gain: float, seed: int):
    """20 s of random steps at 20 Hz on a base with 50 ms latency, 40 ms lags, 50 Hz noisy
    odometry; the base turns at ``turn_gain`` of the commanded rate."""
    plant = UnicyclePlant(PlantConfig(dt=0.01, cmd_latency=0.05, lag_v=0.04, lag_w=0.04,
                                      odom_rate=50.0, odom_noise=(0.001, 0.001, 0.001),
                                      noise_seed=seed))
    rng = np.random.default_rng(seed)
    levels = [(rng.uniform(0.05, 0.4), rng.uniform(-1.0, 1.0)) for _ in range(20)]
    cmd, odom = [], []
    for k in range(2000):
        s = plant.odometry()
        if s is not None:
            odom.append((step_time(s.step, plant.dt), s.x, s.y, s.th, s.v, s.w))
        if k % 5 == 0:
            v, w = levels[k // 100]
            plant.command(v, turn_gain * w)
            cmd.append((step_time(k, plant.dt), v, w))
        plant.advance()
    return CommandSamples(*np.array(cmd).T), OdometrySamples(*np.array(odom).T)


@functools.cache
def _identified(turn_gain: float, seed: int):
    """The identification of :func:`_recording`, from the noisy poses (this plant's twist is
    exact: its gains would have no spread); once per test process."""
    return identify_latency(*_recording(turn_gain, seed), source='pose')


@pytest.mark.parametrize('turn_gain', [1.0, 0.65])
@pytest.mark.parametrize('seed', [1, 2])
def test_the_gains_intervals_hold_the_truth(turn_gain, seed):
    """Measured (seeds 1-4): w 0.6502 (0.6496-0.6511), 0.6498 (0.6486-0.6508), 0.6502
    (0.6493-0.6510), 0.6507 (0.6499-0.6514) for 0.65; 1.0002 (0.9992-1.0011) ... for 1."""
    res = _identified(turn_gain, seed)
    assert res.gain_w_low <= turn_gain <= res.gain_w_high, res
    assert res.gain_v_low <= 1.0 <= res.gain_v_high, res
    assert res.gain_w_low <= res.gain_w <= res.gain_w_high
    assert 0 < res.gain_w_high - res.gain_w_low < 0.05
    assert abs(res.latency_s - 0.05) < 0.011


@pytest.mark.parametrize('turn_gain', [1.0, 0.65])
def test_the_design_plan_compensates_a_gain_that_matters_and_says_what_is_uncovered(turn_gain):
    """A turn gain of 0.65 goes to the tracker's gain_w (the gain file's tracker section via
    the bring-up and latency-design), recorded in the design section with its interval, and
    the plan says the certificate does not cover its remaining uncertainty; a gain of 1 (its
    interval holds 1) is not compensated."""
    from nonfragile_tracker.control.synthesis.latency_design import plan_from_identification
    plan = plan_from_identification(_identified(turn_gain, 1))
    meta = plan.metadata()
    lo, hi = meta['identified_gain_w_interval']
    assert lo <= turn_gain <= hi
    if turn_gain == 1.0:
        assert plan.gain_parameters() == {} and 'channel gain' not in plan.describe()
        assert 'compensated_gain_w' not in meta
    else:
        assert plan.gain_parameters() == {'gain_w': pytest.approx(0.65, abs=0.005)}
        assert meta['compensated_gain_w'] == plan.gain_parameters()['gain_w']
        assert 'gain_w = 0.65' in plan.describe()
        assert "the design's certificate takes it as exact" in plan.describe()


@functools.cache
def _designed():
    """The latency design for the 0.65 turn gain's plan (the bring-up's design, ~7 s)."""
    from nonfragile_tracker.control.synthesis.latency_design import (design_for_latency,
                                                                     plan_from_identification)
    from nonfragile_tracker.control.synthesis.problem import load_problem
    from conftest import CONFIG
    prob = load_problem(CONFIG / 'paper_problem.yaml')
    plan = plan_from_identification(_identified(0.65, 1))
    return prob, plan, design_for_latency(prob, plan.h_min, plan.h_max, lag=plan.lag)


def test_the_turn_gains_remaining_uncertainty_is_certified():
    """The designed gain with the compensated turn gain's remaining uncertainty (+-0.13 %,
    a multiplicative input uncertainty beside the problem's E D F) is certified for the
    residual delay through the lag; the condition holds up to +-36 % (the uncompensated
    skid-steer's 0.64: its feedback loop stays stable, its feedforward is what misses) and
    fails at +-40 % and beyond."""
    from nonfragile_tracker.control.synthesis.latency_design import (
        certify_turn_gain_uncertainty, gain_verdict)
    prob, plan, res = _designed()
    line, record = gain_verdict(plan, prob, res.K)
    assert record['gain_uncertainty_certified'] is True
    assert 0 < record['turn_gain_uncertainty'] < 0.005
    assert 'the gain is certified for the residual delay' in line
    verdicts = [certify_turn_gain_uncertainty(prob, res.K, plan.h_min, plan.h_max, e, plan.lag)
                for e in (0.0, 0.01, 0.1, 0.36, 0.4, 0.8)]
    assert verdicts == [True, True, True, True, False, False]
