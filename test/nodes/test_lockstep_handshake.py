"""Lockstep start-up handshake with a recorder: both DDS sides matched before a step counts.

A publisher matching a subscription does not mean the subscription has matched the
publisher; samples sent in between are dropped by the subscriber.  These tests drive the
nodes' side of the handshake directly (in one process, where matching is immediate, the
conditions are set by which endpoints exist).
"""
import time

import pytest
import rclpy
from geometry_msgs.msg import Twist
from nav_msgs.msg import Odometry
from rclpy.parameter import Parameter
from rosgraph_msgs.msg import Clock
from std_msgs.msg import UInt64

from nonfragile_tracker.interface import topics
from nonfragile_tracker.control.simulation.gains import read_gain_file
from nonfragile_tracker.nodes.common import DATA_QOS, LATCHED_QOS, ns_to_stamp, overrides
from nonfragile_tracker.nodes.plant import PlantNode
from nonfragile_tracker.nodes.recorder import Recorder
from nonfragile_tracker.nodes.tracker import TrackerNode
from nonfragile_tracker.workflows.runner import lockstep_handshake

from conftest import CONFIG, unique_domain_id


@pytest.fixture()
def ctx():
    c = rclpy.Context()
    rclpy.init(context=c, domain_id=unique_domain_id('handshake'))
    yield c
    rclpy.try_shutdown(context=c)


def spin(ex, seconds, until=lambda: False):
    end = time.monotonic() + seconds
    while time.monotonic() < end and not until():
        ex.spin_once(timeout_sec=0.02)
    return until()


def test_handshake_parameters_cover_every_lockstep_publisher():
    # the reference's samples are off the critical path: only the recorder reads them
    assert lockstep_handshake(True) == {
        'plant': {'lockstep_subscribers': 2, 'lockstep_recorder': True},
        'tracker': {'lockstep_subscribers': 2}, 'reference': {'lockstep_subscribers': 1},
        'recorder': {'lockstep_gate': True}}
    assert lockstep_handshake(False)['plant'] == {'lockstep_subscribers': 1,
                                                 'lockstep_recorder': False}


def test_plant_waits_for_the_recorders_announcement(ctx):
    plant = PlantNode(context=ctx, parameter_overrides=overrides(lockstep_recorder=True))
    peer = rclpy.create_node('peer', context=ctx)
    odom = []
    peer.create_publisher(Twist, topics.CMD_VEL, DATA_QOS)
    peer.create_subscription(Odometry, topics.ODOM, odom.append, DATA_QOS)
    peer.create_subscription(Clock, topics.CLOCK, lambda m: None, DATA_QOS)
    ex = rclpy.executors.SingleThreadedExecutor(context=ctx)
    ex.add_node(plant)
    ex.add_node(peer)
    try:
        # every publisher of the plant is matched, but no recorder has said it is ready
        assert not spin(ex, 1.5, lambda: plant.started)
        assert odom == []
        ready = peer.create_publisher(UInt64, topics.RECORDER_READY, LATCHED_QOS)
        ready.publish(UInt64(data=1))
        assert spin(ex, 5.0, lambda: plant.started and len(odom) >= 1)
        assert odom[0].header.stamp.sec == 0 and odom[0].header.stamp.nanosec == 0
    finally:
        plant.destroy_node()
        peer.destroy_node()


def test_tracker_leaves_a_step_unanswered_until_cmd_vel_has_its_subscribers(ctx):
    K = [float(v) for v in read_gain_file(CONFIG / 'tracker_gains.yaml').ravel()]
    tracker = TrackerNode(context=ctx, parameter_overrides=[
        Parameter('K', value=K), Parameter('lockstep_subscribers', value=2)])
    peer = rclpy.create_node('peer', context=ctx)
    got = []
    peer.create_subscription(Twist, topics.CMD_VEL, got.append, DATA_QOS)
    ex = rclpy.executors.SingleThreadedExecutor(context=ctx)
    ex.add_node(tracker)
    ex.add_node(peer)
    msg = Odometry()
    msg.header.frame_id = topics.ODOM_FRAME
    ns_to_stamp(0, msg.header.stamp)
    msg.pose.pose.orientation.w = 1.0
    try:
        spin(ex, 0.5)
        tracker._on_odom(msg)          # one cmd_vel subscriber of two: not consumed
        assert tracker.inputs.last_odom_stamp == -1
        peer.create_subscription(Twist, topics.CMD_VEL, lambda m: None, DATA_QOS)
        assert spin(ex, 5.0, lambda: tracker.pub_cmd.get_subscription_count() >= 2)
        tracker._on_odom(msg)          # the plant's republished step: consumed now
        assert tracker.inputs.last_odom_stamp == 0
    finally:
        tracker.destroy_node()
        peer.destroy_node()


def test_recorder_announces_readiness_and_writes_a_republished_step_once(ctx, tmp_path):
    rec = Recorder(context=ctx, parameter_overrides=overrides(
        output=str(tmp_path / 'bag'), topics=['odom'], lockstep_gate=True, gate_timeout=30.0))
    peer = rclpy.create_node('peer', context=ctx)
    ready = []
    peer.create_subscription(UInt64, topics.RECORDER_READY, ready.append, LATCHED_QOS)
    ex = rclpy.executors.SingleThreadedExecutor(context=ctx)
    ex.add_node(rec)
    ex.add_node(peer)
    try:
        assert not spin(ex, 1.0, lambda: bool(ready))     # odom has no publisher yet
        pub = peer.create_publisher(Odometry, topics.ODOM, DATA_QOS)
        assert spin(ex, 5.0, lambda: bool(ready))
        msg = Odometry()
        msg.header.frame_id = topics.ODOM_FRAME
        for k in (0, 0, 1):                                # step 0 republished once
            ns_to_stamp(k * 10_000_000, msg.header.stamp)
            pub.publish(msg)
        assert spin(ex, 5.0, lambda: rec.counts['odom'] + rec.repeats >= 3)
        assert (rec.counts['odom'], rec.repeats) == (2, 1)
    finally:
        rec.destroy_node()
        peer.destroy_node()
