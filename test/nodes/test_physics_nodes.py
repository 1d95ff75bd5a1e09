"""A MuJoCo base as the plant node's model (``model:
nonfragile_tracker.control.simulation.physics:turtlebot3``): the lockstep run through the nodes
equals the in-process simulation of the same base to round-off (MuJoCo is deterministic across
processes), its odometry is the encoders' and its true pose is on the pose topic; the
skid-steer with the tracker's ``gain_w`` parameter (its turn gain compensated) likewise, and
with its side-slip table (``side_slip_rates``, ``side_slip``) too."""
import math
import os

import numpy as np
import pytest

from nonfragile_tracker.interface import topics
from nonfragile_tracker.bag.reader import read_bag, read_messages
from nonfragile_tracker.control.simulation.gains import read_gain_file
from nonfragile_tracker.control.simulation.plant import PlantConfig
from nonfragile_tracker.control.simulation.tracker import TrackerConfig
from nonfragile_tracker.control.simulation.reference import circle
from nonfragile_tracker.control.simulation.simulate import simulate_tracking
from nonfragile_tracker.workflows.runner import run_processes, scenario_parameters

from conftest import CONFIG, unique_domain_id

DURATION = 4.0
GAINS = CONFIG / 'tracker_gains.yaml'
MODEL = 'nonfragile_tracker.control.simulation.physics:{}'
NO_DELAY = {'tau': 0.0, 'A_tau': [0.0] * 16}


@pytest.mark.parametrize('base, tracker', [
    ('turtlebot3', {'max_linear_speed': 0.22}), ('jackal_skid', {'gain_w': 0.64}),
    ('jackal_skid', {'gain_w': 0.64, 'side_slip_rates': [0.25, 0.5],
                     'side_slip': [0.034, 0.07]})])
def test_a_physics_base_through_the_nodes_equals_the_simulation(tmp_path, base, tracker):
    start = {'initial_pose': [0.5, 0.0, math.pi / 2], 'initial_speed': 0.1}    # on the path
    ov = {'plant': {'ros__parameters': {'duration': DURATION, 'model': MODEL.format(base),
                                        **start, **NO_DELAY}},
          'reference': {'ros__parameters': {'rate': 0.2}},
          'tracker': {'ros__parameters': {**tracker, **NO_DELAY}}}
    params = scenario_parameters(CONFIG / 'paper_scenario.yaml', GAINS, ov)
    env = dict(os.environ, ROS_DOMAIN_ID=str(unique_domain_id('physics')))
    run_dir = tmp_path / 'run'
    run_dir.mkdir()
    res = run_processes(params, run_dir, env=env, progress=lambda s: None,
                        recorder_topics=[*topics.LEAN_TOPICS, topics.POSE])  # + true pose
    assert all(c == 0 for c in res.exit_codes.values()), (res.exit_codes, [
        (p.name, p.read_text()[-2000:]) for p in run_dir.glob('*.log')])
    run = read_bag(res.bag).run                         # odom: the encoder odometry
    truth = {}                                          # the pose topic: the true pose
    for _, msg in read_messages(res.bag, topics.POSE):
        st = msg.header.stamp
        truth[st.sec * 10**9 + st.nanosec] = (msg.pose.position.x, msg.pose.position.y)
    true_xy = np.array([truth[int(ns)] for ns in run.pose.stamp_ns])
    pc = PlantConfig(dt=0.01, x0=0.5, y0=0.0, th0=math.pi / 2, v0=0.1)
    steps = int(round(DURATION / pc.dt))
    sim = simulate_tracking(pc, TrackerConfig(K=read_gain_file(GAINS), **tracker),
                            circle(radius=0.5, rate=0.2), steps, plant=MODEL.format(base))
    assert len(run.pose) == steps + 1 and len(run.commands) == steps + 1
    # the true pose (pose topic) and the commands are the in-process run's; the
    # skid-steer's skidding wheels judder (stick-slip): the nodes' reference (the path
    # published as a trajectory, 1e-14 m from the analytic one) grows apart from the
    # in-process one after about 0.3 s there, so it is compared over its first 0.3 s
    n = steps + 1 if base == 'turtlebot3' else 31
    np.testing.assert_allclose(true_xy[:n, 0], sim.x[:n], rtol=0, atol=1e-9)
    np.testing.assert_allclose(true_xy[:n, 1], sim.y[:n], rtol=0, atol=1e-9)
    np.testing.assert_allclose(run.commands.v[:n], sim.cmd_v[:n], rtol=0, atol=1e-9)
    np.testing.assert_allclose(run.commands.w[:n], sim.cmd_w[:n], rtol=0, atol=1e-9)
    if 'gain_w' in tracker:       # the node divides the law's turn rate by its gain_w
        plain = simulate_tracking(pc, TrackerConfig(K=read_gain_file(GAINS)),
                                  circle(radius=0.5, rate=0.2), 2, plant=MODEL.format(base))
        assert run.commands.w[0] == plain.cmd_w[0] / tracker['gain_w'] != 0.0
    # odom is the encoders': near the true pose, not equal to it (creep, ticks)
    gap = np.hypot(run.pose.x - true_xy[:, 0], run.pose.y - true_xy[:, 1])
    assert 0.0 < gap.max() < 5e-3, gap.max()
    assert float(np.hypot(sim.x[-1] - sim.xd[-1], sim.y[-1] - sim.yd[-1])) < 0.05


def test_two_lockstep_runs_of_a_physics_base_are_bit_identical(tmp_path):
    """The skid-steer (whose judder amplifies any difference, see above) run twice through
    the nodes in lockstep: the encoder odometry, the true pose and the commands of the two
    bags are equal bit for bit."""
    ov = {'plant': {'ros__parameters': {'duration': DURATION, 'model': MODEL.format(
              'jackal_skid'), 'initial_pose': [0.5, 0.0, math.pi / 2], 'initial_speed': 0.1,
              'odom_rate': 50.0, 'odom_noise': [0.001, 0.001, 0.001], 'cmd_latency': 0.04,
              **NO_DELAY}},
          'reference': {'ros__parameters': {'rate': 0.2}},
          'tracker': {'ros__parameters': {'gain_w': 0.64, **NO_DELAY}}}
    params = scenario_parameters(CONFIG / 'paper_scenario.yaml', GAINS, ov)
    runs = []
    for i in range(2):
        env = dict(os.environ, ROS_DOMAIN_ID=str(unique_domain_id(f'physics-rerun-{i}')))
        run_dir = tmp_path / f'run{i}'
        run_dir.mkdir()
        res = run_processes(params, run_dir, env=env, progress=lambda s: None,
                            recorder_topics=[*topics.LEAN_TOPICS, topics.POSE])
        assert all(c == 0 for c in res.exit_codes.values()), res.exit_codes
        run = read_bag(res.bag).run
        truth = [(m.pose.position.x, m.pose.position.y) for _, m in
                 read_messages(res.bag, topics.POSE)]
        runs.append((run.pose.x, run.pose.y, run.pose.th, run.commands.v, run.commands.w,
                     np.array(truth)))
    assert len(runs[0][0]) == 201                      # 4 s of 50 Hz odometry
    for a, b in zip(*runs):
        assert a.shape == b.shape and np.array_equal(a, b)
