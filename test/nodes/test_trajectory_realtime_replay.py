"""A real-time waypoint run, one process per node, re-timed in the background and replayed.

Its own module: the longest real-time test (about 17 s), so that pytest-xdist (whole
modules per worker) can start it first, beside the other real-time modules.
"""
import os

import numpy as np
import pytest

from nonfragile_tracker.control.simulation.gains import read_gain_file
from nonfragile_tracker.interface.msgconv import stamp_ns

from conftest import CONFIG, unique_domain_id

pytestmark = pytest.mark.ros

LAP = CONFIG / 'trajectories' / 'lap.csv'


@pytest.mark.realtime
@pytest.mark.slow
def test_replay_reproduces_a_real_time_waypoint_run_re_timed_in_the_background(tmp_path):
    """Real time, one process per node: the tracker re-times the lap in its worker thread and
    adopts it at the first odometry after that (whenever the re-timing ends), announcing
    that odometry's stamp on tracker/trajectory; bag replay adopts it there and reproduces
    every recorded command exactly (predictor from the gain file).  The run's start gate
    (plant and tracker wait for the recorder's matched subscriptions) puts every odometry
    message and command in the bag."""
    import yaml
    from nonfragile_tracker.bag.replay import replay
    from nonfragile_tracker.workflows.runner import realtime_overrides, run_processes, scenario_parameters
    K = read_gain_file(CONFIG / 'tracker_gains.yaml')
    gains = tmp_path / 'g.yaml'
    gains.write_text(yaml.safe_dump({'/**/tracker': {'ros__parameters': {
        'K': [float(v) for v in np.asarray(K).ravel()], 'K_shape': [2, 4],
        'predict_latency': 0.035, 'predict_lag_v': 0.045, 'predict_lag_w': 0.06}}}))
    scenario_file = CONFIG / 'line_arc_scenario.yaml'
    ov = realtime_overrides()
    ov['reference']['ros__parameters'].update(trajectory_file=str(LAP))
    ov['tracker']['ros__parameters'].update(wait_for_trajectory=True)
    ov['plant']['ros__parameters'].update(initial_pose=[0.0, 0.0, 0.0], duration=14.0)
    params = scenario_parameters(scenario_file, gains, ov)
    env = dict(os.environ, ROS_DOMAIN_ID=str(unique_domain_id('traj_rt_replay')))
    res = run_processes(params, tmp_path, env=env, progress=lambda s: None)
    assert all(c == 0 for c in res.exit_codes.values()), res.exit_codes
    log = (tmp_path / 'tracker.log').read_text()
    assert 're-timed for max_angular_accel' in log        # lap.csv's turns exceed 3 rad/s^2
    rep = replay(res.bag, gains=gains, params=scenario_file)
    assert rep.mode == 'realtime' and len(rep.recorded) > 500
    # adopted where the tracker said, not where a search guessed: the trajectory is fed
    # right before the odometry with the announced stamp, which answers first
    ev = rep.plan.events
    at = next(i for i, e in enumerate(ev) if e.kind == 'trajectory')
    assert rep.plan.adopted_ns is not None
    assert stamp_ns(ev[at + 1].msg.header.stamp) == rep.plan.adopted_ns
    assert rep.commands[0][0] == ev[at + 1].receive_ns
    assert len(rep.commands) == len(rep.recorded)
    assert rep.comparison.equal and rep.max_abs_error <= 1e-9
