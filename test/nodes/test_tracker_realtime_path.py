"""The tracker's real-time odom -> cmd_vel path: same command as the core, published first."""
from __future__ import annotations

import math
import subprocess
import sys

import pytest
import rclpy
from geometry_msgs.msg import AccelStamped, PoseStamped, TwistStamped
from nav_msgs.msg import Odometry
from rclpy.parameter import Parameter

from nonfragile_tracker.workflows import runner
from nonfragile_tracker.interface import topics
from nonfragile_tracker.control.simulation.tracker import Tracker
from nonfragile_tracker.interface.msgconv import fill_pose, ns_to_stamp, pose_from_odom, reference_from_msgs
from nonfragile_tracker.nodes.tracker import TrackerNode

from conftest import CONFIG, ROOT


@pytest.fixture
def node():
    params = runner.scenario_parameters(CONFIG / 'paper_scenario.yaml',
                                        CONFIG / 'tracker_gains.yaml', {
        'tracker': {'ros__parameters': {'mode': 'realtime'}}})['tracker']['ros__parameters']
    context = rclpy.Context()
    rclpy.init(context=context)
    n = TrackerNode(context=context,
                    parameter_overrides=[Parameter(k, value=v) for k, v in params.items()])
    yield n
    n.destroy_node()
    rclpy.try_shutdown(context=context)


class Recorder:
    """Stands in for the cmd_vel publisher: what was sent and the odom receipt time then."""

    def __init__(self, node):
        self.node, self.sent = node, []

    def publish(self, msg):
        self.sent.append((msg.linear.x, msg.angular.z, self.node._last_odom_rx))

    def get_subscription_count(self):
        return 1


def callback(node, topic):
    name = node.resolve_topic_name(topic)
    return next(s for s in node.subscriptions if s.topic_name == name).callback


def test_realtime_command_is_the_core_step_and_goes_out_before_the_bookkeeping(node):
    rec = node.pub_cmd = Recorder(node)
    core = Tracker(node.config.tracker)
    r, w = 0.5, 0.02
    for i in range(50):
        t = 1.0 + 0.01 * i
        stamp = 1_000_000_000 + 10_000_000 * i
        p, tw, ac, od = PoseStamped(), TwistStamped(), AccelStamped(), Odometry()
        for m in (p, tw, ac, od):
            m.header.frame_id = topics.ODOM_FRAME
            ns_to_stamp(stamp, m.header.stamp)
        fill_pose(p.pose, r * math.cos(w * t), r * math.sin(w * t), w * t + math.pi / 2)
        tw.twist.linear.x, tw.twist.linear.y = -r * w * math.sin(w * t), r * w * math.cos(w * t)
        ac.accel.linear.x, ac.accel.linear.y = -r * w * w * math.cos(w * t), \
            -r * w * w * math.sin(w * t)
        fill_pose(od.pose.pose, 0.51 + 1e-3 * i, 0.02, math.pi / 2 - 0.05)
        od.twist.twist.linear.x = 0.01
        for topic, m in ((topics.REF_POSE, p), (topics.REF_TWIST, tw), (topics.REF_ACCEL, ac)):
            callback(node, topic)(m)
        before = node._last_odom_rx
        callback(node, topics.ODOM)(od)
        x, y, th = pose_from_odom(od.pose.pose)
        cmd = core.step(x, y, th, reference_from_msgs(stamp * 1e-9, p, tw, ac),
                        measured_speed=0.01, stamp=stamp * 1e-9)
        v_sent, w_sent, rx_at_publish = rec.sent[-1]
        c = node.config.tracker
        assert v_sent == max(-c.max_linear_speed, min(c.max_linear_speed, cmd.v))
        assert w_sent == max(-c.max_angular_speed, min(c.max_angular_speed, cmd.w))
        assert rx_at_publish == before                 # receipt time read after the publish
        assert node._last_odom_rx > before and node._last_odom_wall == node._last_odom_rx
    assert len(rec.sent) == 50 and node.commands == 50


def test_a_node_process_freezes_its_start_up_objects():
    code = ('import gc; from nonfragile_tracker.nodes.common import freeze_startup_objects; '
            'freeze_startup_objects(); print(gc.get_freeze_count(), len(gc.get_objects()))')
    out = subprocess.run([sys.executable, '-c', code], cwd=ROOT, capture_output=True,
                         text=True, check=True, timeout=60).stdout.split()
    frozen, tracked = int(out[0]), int(out[1])
    assert frozen > 10_000 and tracked < 100       # a full collection walks almost nothing
