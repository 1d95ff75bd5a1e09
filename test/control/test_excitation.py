"""The bring-up's excitation plan: inside the box, within the limits, informative, short."""
from __future__ import annotations

import math

import numpy as np
import pytest

from conftest import CONFIG
from nonfragile_tracker.control.identification.excitation import (
    FAST_LINEAR_ACCEL, GENTLE_ANGULAR_ACCEL, GENTLE_LINEAR_ACCEL, ExcitationError, margin_for, plan_excitation,
    plan_trial)
from nonfragile_tracker.control.simulation.follow import simulate_following
from nonfragile_tracker.control.simulation.gains import read_gain_file
from nonfragile_tracker.control.simulation.plant import PlantConfig
from nonfragile_tracker.control.simulation.tracker import TrackerConfig


@pytest.mark.parametrize('box', [0.4, 1.0, 3.0])
@pytest.mark.parametrize('vmax, wmax', [(0.3, 1.0), (1.0, 3.0)])
@pytest.mark.parametrize('rate', [10.0, 200.0])
@pytest.mark.parametrize('accel', [False, True])
def test_extent_inside_the_box_and_the_limits(box, vmax, wmax, rate, accel):
    plan = plan_excitation(box, vmax, wmax, accel_segment=accel, odom_rate=rate)
    ext = plan.extent()
    # the reference keeps at least half the margin for the tracking error
    assert ext.max_distance <= box - 0.5 * margin_for(box)
    assert ext.max_speed <= vmax + 1e-12
    assert ext.max_turn_rate <= wmax + 1e-9
    assert ext.duration <= 60.0
    assert plan.v[0] == 0.0 and plan.v[-1] == 0.0          # from rest, to rest
    # the same figures from the trajectory the node follows (in another start pose)
    traj = plan.trajectory((2.0, -1.0, 0.7))
    s = traj.evaluate(np.linspace(0.0, plan.duration, 2001))
    d = np.hypot(s.x - 2.0, s.y + 1.0)
    assert d.max() == pytest.approx(ext.max_distance, abs=2e-3)
    # informative: steps in v and in w, each held long enough for 25 odometry periods
    levels = {round(float(v), 6) for v in plan.v}
    assert len(levels) >= 4
    assert np.ptp(plan.w) >= 0.5 * ext.max_turn_rate          # w changes sign: large w steps
    holds = [t1 - t0 for name, t0, t1 in plan.segments if name.startswith('step')]
    assert min(holds) >= 25.0 / rate


def test_the_turns_reach_a_laps_when_the_speed_allows_at_gentle_ramps():
    """At 0.5 m/s and 2 rad/s in a 1 m box the figure eight turns at 1 rad/s (a lap's 0.4 m
    arcs at 0.4 m/s, where a skid-steer's side slip grows; CLOTHOID_RADII), and the turn
    rate still changes at the gentle ramps outside the acceleration segment: the clothoid's
    plus a gentle speed ramp on the circle's curvature."""
    plan = plan_excitation(1.0, 0.5, 2.0, accel_segment=False)
    ext = plan.extent()
    assert ext.max_turn_rate >= 1.0 and ext.max_speed <= 0.5
    assert ext.max_distance <= 1.0 - 0.5 * margin_for(1.0)
    dw = np.diff(plan.w) / np.diff(plan.t)
    assert np.abs(dw).max() <= (GENTLE_ANGULAR_ACCEL + GENTLE_LINEAR_ACCEL / plan.radius) \
        * (1 + 1e-9)
    # the default limits: the turns of the 0.3 m/s bring-up (the speed binds, not the ramp)
    assert plan_excitation(1.0).extent().max_turn_rate == pytest.approx(0.6, abs=0.01)


def test_ramps_gentle_without_the_accel_segment_fast_with_it():
    gentle = plan_excitation(1.0, accel_segment=False).extent()
    fast = plan_excitation(1.0).extent()                  # the default: with it
    assert gentle.max_linear_accel == pytest.approx(GENTLE_LINEAR_ACCEL)
    assert fast.max_linear_accel == pytest.approx(FAST_LINEAR_ACCEL)
    # known limits (robot file): never exceeded, and no acceleration segment needed
    known = plan_excitation(1.0, accel_segment=True, max_linear_accel=0.25,
                            max_angular_accel=0.8)
    assert known.extent().max_linear_accel <= 0.25 + 1e-12
    assert known.notes and 'known' in known.notes[0]


def test_too_small_a_box_is_refused_with_what_to_change():
    with pytest.raises(ExcitationError, match='at least 0.3 m'):
        plan_excitation(0.1)
    with pytest.raises(ExcitationError, match='larger box or a larger max turn rate'):
        plan_excitation(0.4, 0.3, 0.05)
    with pytest.raises(ExcitationError, match='finite number > 0'):
        plan_excitation(1.0, math.nan)


@pytest.mark.parametrize('box', [0.5, 1.0, 2.0])
def test_trial_continues_inside_the_box(box):
    exc = plan_excitation(box, accel_segment=True)
    trial = plan_trial(exc, duration=20.0)
    assert trial.x[0] == pytest.approx(exc.x[-1]) and trial.y[0] == pytest.approx(exc.y[-1])
    assert trial.extent().max_distance <= box - 0.5 * margin_for(box)
    assert trial.duration == pytest.approx(20.0, abs=1.0)
    assert exc.duration + trial.duration <= 90.0


@pytest.mark.parametrize('latency, lag, accel', [(0.04, 0.03, (1.0, 3.0)),
                                                  (0.3, 0.08, (0.5, 1.5)),
                                                  (0.3, 0.08, (1.0, 3.0))])
def test_shipped_gain_keeps_the_box_on_unknown_bases(latency, lag, accel):
    """Closed loop with the shipped certified gain (in process, the node's law and follower):
    the robot stays inside the default 1 m box on the benchmark's slowest bases."""
    plan = plan_excitation(1.0, 0.3, 1.0, accel_segment=True)
    K = read_gain_file(CONFIG / 'tracker_gains.yaml')
    pc = PlantConfig(dt=0.01, cmd_latency=latency, lag_v=lag, lag_w=lag, odom_rate=50,
                     odom_noise=(1e-3, 1e-3, 1e-3), noise_seed=1, max_linear_accel=accel[0],
                     max_angular_accel=accel[1])
    tc = TrackerConfig(K=tuple(map(tuple, K.tolist())), dt=0.02, max_linear_speed=0.3,
                       max_angular_speed=1.0)
    run = simulate_following(pc, tc, plan.trajectory(), int(plan.duration / 0.01) + 100)
    assert np.max(np.hypot(run.x, run.y)) < 1.0 - 0.05
    assert np.max(np.abs(run.cmd_v)) <= 0.3 + 1e-12
    assert np.max(np.abs(run.cmd_w)) <= 1.0 + 1e-12
