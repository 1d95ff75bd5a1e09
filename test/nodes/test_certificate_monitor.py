"""The tracker's certificate monitor through the nodes: a latency step from 100 to 250 ms
turns the status on tracker/certificate and /diagnostics from OK to ERROR, and the
monitor (adaptation off) leaves the lockstep command sequence bit for bit as the
in-process simulation computes it."""
import math

import numpy as np
import pytest

from nonfragile_tracker.control.simulation.gains import read_gain_file
from nonfragile_tracker.control.simulation.plant import PlantConfig
from nonfragile_tracker.control.simulation.tracker import TrackerConfig
from nonfragile_tracker.control.simulation.follow import simulate_following

from conftest import CONFIG
import test_trajectory_nodes
from test_trajectory_nodes import param_list, spin_nodes

ros_context = test_trajectory_nodes.ros_context       # the fixture, shared

pytestmark = pytest.mark.ros

DURATION, STEP = 14.0, 7.0
SCHEDULE = [STEP, 0.25]
# the worker thread estimates on wall time (monitor_period); a lockstep run covers ~7 s of
# simulated time per wall second, so the test makes the estimates itself, every ESTIMATE s of
# simulated time, and the thread (period one hour) stays out of the way
CERT = {'certified_residual': [0.0, 0.1], 'certified_lag': 0.05,
        'certified_adapt_range': [0.095, 0.105], 'monitor_period': 3600.0,
        'monitor_window': 3.0, 'diagnostics_period': 0.5}
ESTIMATE = 0.5


def test_latency_step_turns_the_certificate_status_to_error(ros_context):  # noqa: F811
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
    from geometry_msgs.msg import Twist
    from rclpy.node import Node
    from nonfragile_tracker.nodes.common import DATA_QOS
    from nonfragile_tracker.nodes.plant import PlantNode
    from nonfragile_tracker.nodes.reference import ReferenceNode
    from nonfragile_tracker.nodes.tracker import TrackerNode
    from nonfragile_tracker.workflows.runner import scenario_parameters

    ctx = ros_context
    params = scenario_parameters(CONFIG / 'latency_scenario.yaml', CONFIG / 'tracker_gains.yaml',
                                 {'plant': {'ros__parameters': {'duration': DURATION}},
                                  'tracker': {'ros__parameters': {'wait_for_trajectory': True}}})
    from trajectory_msgs.msg import MultiDOFJointTrajectory
    from nonfragile_tracker.nodes.common import LATCHED_QOS
    from nonfragile_tracker.nodes.trajectory_io import multidof_to_trajectory
    got = {'cert': [], 'diag': [], 'cmd': [], 'traj': []}
    test = Node('test_listener', context=ctx)
    test.create_subscription(DiagnosticArray, 'tracker/certificate', got['cert'].append,
                             DATA_QOS)
    test.create_subscription(DiagnosticArray, '/diagnostics', got['diag'].append, DATA_QOS)
    test.create_subscription(Twist, 'cmd_vel', got['cmd'].append, DATA_QOS)
    test.create_subscription(MultiDOFJointTrajectory, 'trajectory_multidof', got['traj'].append,
                             LATCHED_QOS)
    tracker = TrackerNode(context=ctx, parameter_overrides=param_list(params, 'tracker', **CERT))
    reference = ReferenceNode(context=ctx, parameter_overrides=param_list(
        params, 'reference', horizon=DURATION + 5.0))
    plant = PlantNode(context=ctx, parameter_overrides=param_list(
        params, 'plant', lockstep_subscribers=1, cmd_latency_schedule=SCHEDULE))
    nodes = [test, tracker, reference, plant]
    steps = int(round(DURATION / 0.01))
    marks = [ESTIMATE * i for i in range(1, int(DURATION / ESTIMATE) + 1)]

    def estimate_on_sim_time():
        # one estimate (and its status published) each time the odometry passes a mark
        while marks and tracker.inputs.last_odom_stamp * 1e-9 >= marks[0] - 1e-9:
            marks.pop(0)
            tracker.monitor.update()
            tracker._diagnostics()
        return plant.finished and len(got['cmd']) > steps // 2

    spin_nodes(nodes, estimate_on_sim_time, ctx, timeout=60.0)
    try:
        assert plant.finished and plant.exit_code == 0
        # one more estimate of the window at the very end, its status published
        n_cert, n_diag = len(got['cert']), len(got['diag'])
        tracker.monitor.stop()
        tracker.monitor.update()
        tracker._diagnostics()
        spin_nodes(nodes, lambda: len(got['cert']) > n_cert and len(got['diag']) > n_diag,
                   ctx, timeout=10.0)
        # the monitor does not touch the law: commands as the in-process simulation's
        p = params['plant']['ros__parameters']
        t = params['tracker']['ros__parameters']
        pc = PlantConfig(dt=p['dt'], x0=p['initial_pose'][0], y0=p['initial_pose'][1],
                         th0=p['initial_pose'][2], cmd_latency=p['cmd_latency'],
                         lag_v=p['lag_v'], lag_w=p['lag_w'], odom_rate=p['odom_rate'],
                         odom_noise=tuple(p['odom_noise']), noise_seed=p['noise_seed'],
                         cmd_latency_schedule=tuple(SCHEDULE))
        tc = TrackerConfig(K=read_gain_file(CONFIG / 'tracker_gains.yaml'), dt=t['dt'],
                           predict_latency=t['predict_latency'],
                           predict_lag_v=t['predict_lag_v'], predict_lag_w=t['predict_lag_w'])
        traj, _ = multidof_to_trajectory(got['traj'][0], frame='odom', source='test')
        sim = simulate_following(pc, tc, traj, steps)
        sent = sim.cmd_w[sim.commanded > 0]
        n = len(got['cmd'])
        np.testing.assert_allclose([m.angular.z for m in got['cmd']], sent[:n], rtol=0,
                                   atol=1e-9)
        # statuses: the topic's one status is the one on /diagnostics, named for the node
        statuses = [a.status[0] for a in got['cert']]
        assert statuses and all(s.name == 'tracker: certificate' for s in statuses)
        in_diag = [s for a in got['diag'] for s in a.status if s.name == 'tracker: certificate']
        assert len(in_diag) == len(statuses)

        def window_end(s):
            vals = {kv.key: kv.value for kv in s.values}
            return float(vals.get('window end (s)', 'nan'))

        before = [s for s in statuses if window_end(s) < STEP - 0.5]
        after = [s for s in statuses if window_end(s) > STEP + 3.0]
        assert any(s.level == DiagnosticStatus.OK for s in before)
        assert all(s.level != DiagnosticStatus.ERROR for s in before)
        assert after and all(s.level == DiagnosticStatus.ERROR for s in after), [
            (window_end(s), s.level, s.message) for s in after]
        vals = {kv.key: kv.value for kv in after[-1].values}
        assert abs(float(vals['latency estimate (s)']) - 0.25) <= 0.01    # one plant step
        assert vals['certified latency (s)'] == '[0.1000, 0.1800]'
        assert 'latency-design' in after[-1].message and 'above' in after[-1].message
        ok = {kv.key: kv.value for kv in before[-1].values}
        assert abs(float(ok['latency estimate (s)']) - 0.1) <= 0.01
        assert math.isfinite(window_end(after[-1]))
    finally:
        for nd in nodes:
            nd.destroy_node()
