"""Lockstep with a late, lagging, decimated, noisy plant and the tracker's predictor: the
node processes are deterministic and equal to the in-process simulation; the latency
parameters are validated by the nodes."""
import os

import numpy as np
import pytest
import rclpy
from rclpy.parameter import Parameter

from nonfragile_tracker.bag.reader import read_messages
from nonfragile_tracker.control.simulation.gains import read_gain_file
from nonfragile_tracker.control.simulation.tracker import TrackerConfig
from nonfragile_tracker.control.simulation.reference import circle
from nonfragile_tracker.control.simulation.follow import simulate_following
from nonfragile_tracker.control.simulation.trajectory import Trajectory
from nonfragile_tracker.nodes.common import StartupError
from nonfragile_tracker.nodes.plant import PlantNode
from nonfragile_tracker.nodes.tracker import TrackerNode
from nonfragile_tracker.workflows.runner import run_composed, run_processes, scenario_parameters

from nonfragile_tracker.interface.scenario import paper_plant_config

from conftest import CONFIG, unique_domain_id

pytestmark = pytest.mark.ros

DURATION = 3.0
STEPS = 300
PLANT = dict(cmd_latency=0.05, lag_v=0.05, lag_w=0.03, max_linear_accel=2.0,
             max_angular_accel=5.0, odom_latency=0.03, odom_rate=50.0,
             odom_noise=[0.001, 0.001, 0.002], noise_seed=7)
TRACKER = dict(dt=0.02, predict_latency=0.05, predict_odom_latency=0.03, predict_lag_v=0.05,
               predict_lag_w=0.03)
#: The tracker told the base's acceleration limits (it rate-limits and predicts with them).
LIMITS = dict(max_linear_accel=2.0, max_angular_accel=5.0)


def parameters(limits: bool = False):
    tracker = dict(TRACKER, **LIMITS) if limits else TRACKER
    ov = {'plant': {'ros__parameters': dict(PLANT, duration=DURATION)},
          'tracker': {'ros__parameters': tracker}}
    return scenario_parameters(CONFIG / 'paper_scenario.yaml', CONFIG / 'tracker_gains.yaml', ov)


def simulation(limits: bool = False):
    pc = paper_plant_config(**dict(PLANT, odom_noise=tuple(PLANT['odom_noise'])))
    tracker = dict(TRACKER, **LIMITS) if limits else TRACKER
    tc = TrackerConfig(K=read_gain_file(CONFIG / 'tracker_gains.yaml'), A_tau=pc.A_tau,
                       tau=pc.tau, **tracker)
    # the tracker samples the trajectory at the time its command acts (Follower), as the
    # in-process following does; the path is the exact circle
    return simulate_following(pc, tc, Trajectory.analytic(circle()), STEPS)


def _first_per_stamp(rows):
    """Rows with a header stamp not seen before: a lockstep step the plant republished
    (``lockstep_retry``, under load) is recorded twice; the bag reader drops it too."""
    seen, out = set(), []
    for row in rows:
        if row[0] not in seen:
            seen.add(row[0])
            out.append(row)
    return out


def recorded(bag):
    pose = np.array(_first_per_stamp(
        (m.header.stamp.sec * 10**9 + m.header.stamp.nanosec, m.pose.position.x,
         m.pose.position.y) for _, m in read_messages(bag, 'pose')))
    odom = np.array([r[0] for r in _first_per_stamp(
        (m.header.stamp.sec * 10**9 + m.header.stamp.nanosec,)
        for _, m in read_messages(bag, 'odom'))])
    cmd = np.array([(m.linear.x, m.angular.z) for _, m in read_messages(bag, 'cmd_vel')])
    return pose, odom, cmd


@pytest.fixture(scope='module')
def runs(tmp_path_factory):
    tmp = tmp_path_factory.mktemp('latency')
    env = dict(os.environ, ROS_DOMAIN_ID=str(unique_domain_id('latency')))
    out = {}
    for name in ('processes', 'composed', 'limits'):
        run_dir = tmp / name
        run_dir.mkdir()
        # the true pose at every step is needed: record every topic (the lean default
        # has odom and cmd_vel only)
        if name == 'composed':
            res = run_composed(parameters(), run_dir, record_all=True)
        else:
            res = run_processes(parameters(limits=name == 'limits'), run_dir, env=env,
                                progress=lambda s: None, record_all=True)
        assert all(c == 0 for c in res.exit_codes.values()), (res.exit_codes, [
            (p.name, p.read_text()[-2000:]) for p in run_dir.glob('*.log')])
        out[name] = recorded(res.bag)
    return out


@pytest.mark.parametrize('limits', [False, True], ids=['no-limits', 'limits'])
def test_lockstep_with_latency_equals_the_simulation(runs, limits):
    pose, odom, cmd = runs['limits' if limits else 'processes']
    sim = simulation(limits)
    commanded = sim.commanded.astype(bool)
    # odom: measured every 2nd step, published 3 steps later with the measurement stamp
    expected = [k * 10_000_000 for k in range(0, STEPS - 3 + 1, 2)]
    assert odom.tolist() == expected and commanded.sum() == len(expected)
    assert len(pose) == STEPS + 1 and len(cmd) == len(expected)
    np.testing.assert_array_equal(pose[:, 0], np.arange(STEPS + 1) * 10_000_000)
    np.testing.assert_allclose(pose[:, 1], sim.x, rtol=0, atol=1e-9)
    np.testing.assert_allclose(pose[:, 2], sim.y, rtol=0, atol=1e-9)
    np.testing.assert_allclose(cmd[:, 0], sim.cmd_v[commanded], rtol=0, atol=1e-9)
    np.testing.assert_allclose(cmd[:, 1], sim.cmd_w[commanded], rtol=0, atol=1e-9)
    assert np.ptp(cmd[:, 1]) > 0.1                      # the loop really steered
    if limits:                   # the rate limit binds on w and holds on both (dt = 0.02 s)
        step = np.abs(np.diff(cmd, axis=0))
        assert np.all(step[:, 0] <= LIMITS['max_linear_accel'] * 0.02 + 1e-12)
        assert np.all(step[:, 1] <= LIMITS['max_angular_accel'] * 0.02 + 1e-12)
        assert np.sum(step[:, 1] >= LIMITS['max_angular_accel'] * 0.02 - 1e-12) >= 3


def test_lockstep_with_latency_is_deterministic(runs):
    a, b = runs['processes'], runs['composed']
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x, y)


@pytest.fixture(scope='module')
def context():
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=unique_domain_id('latency-params'))
    yield ctx
    rclpy.try_shutdown(context=ctx)


@pytest.mark.parametrize('params, message', [
    ({'odom_rate': 500.0}, 'odom_rate = 500.0 Hz is above the plant rate'),
    ({'odom_noise': [0.1, 0.1]}, 'odom_noise needs 3'),
    ({'noise_seed': -3}, 'noise_seed must be an integer >= 0'),
    ({'odom_latency': 0.6}, 'must each be at most 50 plant steps in lockstep'),
])
def test_plant_refuses_bad_latency_parameters(context, params, message):
    with pytest.raises(StartupError, match=message):
        PlantNode(context=context,
                  parameter_overrides=[Parameter(k, value=v) for k, v in params.items()])


def test_latency_parameters_reach_the_core(context):
    plant = PlantNode(context=context, parameter_overrides=[
        Parameter(k, value=v) for k, v in PLANT.items()])
    K = [float(v) for v in read_gain_file(CONFIG / 'tracker_gains.yaml').ravel()]
    tracker = TrackerNode(context=context, parameter_overrides=[
        Parameter('K', value=K), *(Parameter(k, value=v) for k, v in TRACKER.items()),
        *(Parameter(k, value=v) for k, v in LIMITS.items())])
    try:
        c = plant.plant.config
        assert (plant.plant.cmd_delay, c.odometry.latency_steps, c.odometry.period_steps) == \
            (5, 3, 2)
        assert (c.lag_v, c.lag_w, c.odom_noise, c.noise_seed) == (0.05, 0.03,
                                                                  (0.001, 0.001, 0.002), 7)
        p = tracker.tracker.predictor
        assert p is not None and p.horizon == pytest.approx(0.08)
        assert (p.actuator.lag_v, p.actuator.lag_w) == (0.05, 0.03)
        assert (p.actuator.max_linear_accel, p.actuator.max_angular_accel) == (2.0, 5.0)
        tc = tracker.tracker.config
        assert (tc.max_linear_accel, tc.max_angular_accel) == (2.0, 5.0) and tc.rate_limited
        for name in LIMITS:
            res = tracker.set_parameters([Parameter(name, value=1.0)])[0]
            assert not res.successful                    # read-only: fixed at start
        res = tracker.set_parameters([Parameter('predict_latency', value=0.1)])[0]
        assert not res.successful                        # read-only: fixed at start
    finally:
        plant.destroy_node()
        tracker.destroy_node()


@pytest.mark.parametrize('name', list(LIMITS))
def test_tracker_refuses_a_negative_acceleration_limit(context, name):
    """The descriptor's range (>= 0, like every tracker limit) refuses it at start."""
    from rclpy.exceptions import InvalidParameterValueException
    K = [float(v) for v in read_gain_file(CONFIG / 'tracker_gains.yaml').ravel()]
    with pytest.raises(InvalidParameterValueException, match=name):
        TrackerNode(context=context, parameter_overrides=[
            Parameter('K', value=K), Parameter(name, value=-1.0)])
