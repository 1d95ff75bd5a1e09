"""Bag-based regression: golden bags re-run, replayed into a fresh tracker, readable diffs."""
import os
import time

import numpy as np
import pytest
import rclpy
from geometry_msgs.msg import AccelStamped, PoseStamped, Twist, TwistStamped
from nav_msgs.msg import Odometry
from rclpy.parameter import Parameter

from nonfragile_tracker.workflows import golden
from nonfragile_tracker.bag.compare import compare_bags, format_differences
from nonfragile_tracker.bag.reader import read_messages
from nonfragile_tracker.control.simulation.gains import read_gain_file
from nonfragile_tracker.nodes.common import DATA_QOS
from nonfragile_tracker.nodes.tracker import TrackerNode
from nonfragile_tracker.interface.scenario import node_parameters

from conftest import unique_domain_id

#: Depends on linear algebra: make test runs it again under a second BLAS kernel (Makefile).
pytestmark = pytest.mark.numerical


@pytest.mark.parametrize('name', sorted(golden.SCENARIOS))
def test_rerun_matches_golden_bag(name, tmp_path):
    """(a) the scenario through the three node processes reproduces the golden bag."""
    env = dict(os.environ, ROS_DOMAIN_ID=str(unique_domain_id('golden' + name)))
    new = golden.run_scenario(golden.SCENARIOS[name], tmp_path / name, env=env)
    cmp = compare_bags(golden.golden_bag(name), new, atol=golden.ATOL)
    assert cmp.equal, format_differences(cmp)
    assert set(cmp.messages) == {'/odom', '/reference/pose', '/reference/twist',
                                 '/reference/accel', '/cmd_vel'}
    assert all(n == 251 for n in cmp.messages.values())


def _golden_raw(bag, topic):
    """(receive ns, raw CDR bytes) of a topic in the golden bag."""
    from nonfragile_tracker.bag.reader import open_reader
    reader = open_reader(bag)
    try:
        conns = [c for c in reader.connections if c.topic == topic]
        return [(ts, bytes(raw)) for _, ts, raw in reader.messages(connections=conns)]
    finally:
        reader.close()


@pytest.mark.parametrize('name, delta', [('paper', [0.0] * 4), ('delta2', [1.0, 0.0, 0.0, 1.0])])
def test_replay_inputs_into_a_fresh_tracker(name, delta):
    """(b) recorded reference and odom, replayed over DDS, give the recorded cmd_vel."""
    bag = golden.golden_bag(name)
    inputs = {t: _golden_raw(bag, '/' + t) for t in ('reference/pose', 'reference/twist',
                                                     'reference/accel', 'odom')}
    expected = [(m.linear.x, m.angular.z) for _, m in read_messages(bag, 'cmd_vel')]
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=unique_domain_id('replay' + name))
    K = read_gain_file(golden.golden_gains())
    tracker = TrackerNode(context=ctx, parameter_overrides=[
        Parameter('K', value=[float(v) for v in K.ravel()]), Parameter('Delta', value=delta),
        Parameter('F', value=node_parameters('tracker')['F'])])   # the scenario's F
    player = rclpy.create_node('player', context=ctx)
    types = {'reference/pose': PoseStamped, 'reference/twist': TwistStamped,
             'reference/accel': AccelStamped, 'odom': Odometry}
    pubs = {t: player.create_publisher(types[t], t, DATA_QOS) for t in types}
    got = []
    player.create_subscription(Twist, 'cmd_vel', lambda m: got.append((m.linear.x, m.angular.z)),
                               DATA_QOS)
    ex = rclpy.executors.SingleThreadedExecutor(context=ctx)
    ex.add_node(tracker)
    ex.add_node(player)
    try:
        deadline = time.monotonic() + 20
        while not all(p.get_subscription_count() >= 1 for p in pubs.values()) \
                or tracker.pub_cmd.get_subscription_count() < 1:
            ex.spin_once(timeout_sec=0.01)
            assert time.monotonic() < deadline, 'tracker and player did not match'
        for k in range(len(expected)):
            for t in types:                   # one step, like ros2 bag play in lockstep
                pubs[t].publish(inputs[t][k][1])
            step_deadline = time.monotonic() + 5
            while len(got) < k + 1:
                ex.spin_once(timeout_sec=0.01)
                assert time.monotonic() < step_deadline, f'no command for step {k}'
    finally:
        tracker.destroy_node()
        player.destroy_node()
        rclpy.try_shutdown(context=ctx)
    np.testing.assert_allclose(np.array(got), np.array(expected), rtol=0, atol=1e-12)


def test_differences_are_readable(tmp_path):
    """(c) a mismatch names the topic, message index, field, expected and got."""
    cmp = compare_bags(golden.golden_bag('paper'), golden.golden_bag('delta2'), atol=golden.ATOL)
    assert not cmp.equal
    text = format_differences(cmp)
    first = cmp.differences[0]
    # the first command is the measured speed in both (no interval known yet, no ramp; its
    # turn rate at the limit): the gains part from the second
    assert first.topic == '/cmd_vel' and first.index == 1
    assert first.field in ('linear.x', 'angular.z')
    assert f'/cmd_vel[1] {first.field}: expected {first.expected!r}, got {first.got!r}' in text


def test_golden_bags_are_small():
    for name in golden.SCENARIOS:
        size = sum(p.stat().st_size for p in golden.golden_bag(name).iterdir())
        assert size < 400_000, (name, size)


def test_republished_steps_do_not_count_as_differences(tmp_path):
    """A lockstep step republished while the plant waited (same header stamp) is dropped."""
    from nonfragile_tracker.bag.reader import open_reader
    from nonfragile_tracker.bag.writer import BagWriter
    src = golden.golden_bag('paper')
    reader = open_reader(src)
    try:
        conns = {c.topic: c.msgtype for c in reader.connections}
        msgs = [(c.topic, ts, bytes(raw)) for c, ts, raw in reader.messages()]
    finally:
        reader.close()
    first_odom = next(m for m in msgs if m[0] == '/odom')
    with BagWriter(tmp_path / 'dup', connections=conns) as w:
        for topic, ts, raw in msgs:
            w.write(topic, ts, raw)
            if (topic, ts, raw) == first_odom:
                w.write(topic, ts + 1, raw)          # the plant's retry of step 0
    cmp = compare_bags(src, tmp_path / 'dup', atol=golden.ATOL)
    assert cmp.equal and cmp.repeats == {'/odom': 1}
