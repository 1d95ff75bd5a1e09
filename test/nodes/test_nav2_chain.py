"""The Nav2 chain: the tracker publishes ``cmd_vel_nav`` (the launch files' remapping), a
stand-in collision monitor scales or zeroes it on the way to ``cmd_vel``; the tracker notices,
its compensator does not wind up, and it drives on when released.  Lockstep, in one process:
the test is the base (a unicycle integrating ``cmd_vel``) and publishes the odometry.  And a
planner's plan replaced every 0.5 s in real time (the re-timing in the tracker's worker
thread): spliced, no stop."""
import math
import time

import numpy as np
import pytest
import rclpy
from geometry_msgs.msg import PoseStamped, Twist
from nav_msgs.msg import Odometry, Path
from rclpy.parameter import Parameter

from nonfragile_tracker.interface import topics
from nonfragile_tracker.control.simulation.gains import read_gain_file
from nonfragile_tracker.nodes.common import (DATA_QOS, LATCHED_QOS, fill_pose, make_executor,
                                             ns_to_stamp)
from nonfragile_tracker.nodes.tracker import TrackerNode

from conftest import CONFIG, unique_domain_id

DT_NS = 20_000_000
CRUISE = 0.4
K = [float(v) for v in read_gain_file(CONFIG / 'tracker_gains.yaml').ravel()]


class CollisionMonitor:
    """Nav2's collision_monitor, stood in: cmd_vel_nav * scale -> cmd_vel."""

    def __init__(self, context):
        self.node = rclpy.create_node('collision_monitor', context=context)
        self.scale = 1.0
        self.pub = self.node.create_publisher(Twist, topics.CMD_VEL, DATA_QOS)
        self.heard = []
        self.node.create_subscription(Twist, topics.CMD_VEL_NAV, self._relay, DATA_QOS)

    def _relay(self, msg):
        self.heard.append(msg.linear.x)
        out = Twist()
        out.linear.x, out.angular.z = msg.linear.x * self.scale, msg.angular.z * self.scale
        self.pub.publish(out)


def test_a_collision_monitor_stops_and_slows_the_tracker_which_recovers():
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=unique_domain_id('nav2_chain'))
    tracker = TrackerNode(context=ctx, cli_args=['--ros-args', '-r',
                                                 f'{topics.CMD_VEL}:={topics.CMD_VEL_NAV}'],
                          parameter_overrides=[Parameter(k, value=v) for k, v in {
                              'K': K, 'mode': 'lockstep', 'wait_for_trajectory': True,
                              'monitor': False, 'cruise_speed': CRUISE, 'max_accel': 0.5,
                              'override_tolerance': 0.1}.items()])
    monitor = CollisionMonitor(ctx)
    base = rclpy.create_node('base', context=ctx)
    odom_pub = base.create_publisher(Odometry, topics.ODOM, DATA_QOS)
    plan_pub = base.create_publisher(Path, topics.TRAJECTORY, LATCHED_QOS)
    got = []
    base.create_subscription(Twist, topics.CMD_VEL, lambda m: got.append((m.linear.x,
                                                                           m.angular.z)),
                             DATA_QOS)
    ex = make_executor(ctx)
    for n in (tracker, monitor.node, base):
        ex.add_node(n)

    def spin_until(done, timeout=5.0):
        end = time.monotonic() + timeout
        while not done() and time.monotonic() < end:
            ex.spin_once(timeout_sec=0.01)
        return done()

    try:
        assert spin_until(lambda: odom_pub.get_subscription_count() and
                          monitor.pub.get_subscription_count() and
                          tracker.pub_cmd.get_subscription_count())
        plan = Path()
        plan.header.frame_id = 'odom'
        for i in range(81):                         # 4 m straight, 5 cm apart
            ps = PoseStamped()
            fill_pose(ps.pose, 0.05 * i, 0.0, 0.0)
            plan.poses.append(ps)
        plan_pub.publish(plan)
        # taken before the first odometry: its origin is 0, the run re-based to start at the
        # first odometry (0.2 s late), whatever DDS delivers first
        assert spin_until(lambda: tracker.inputs.follower is not None)
        x = v = 0.0
        xs, sent = [], []
        for k in range(10, 760):                    # 15 s
            t = k * DT_NS * 1e-9
            monitor.scale = 0.0 if 3.0 <= t < 5.0 else 0.5 if 6.0 <= t < 7.0 else 1.0
            m = Odometry()
            m.header.frame_id = 'odom'
            ns_to_stamp(k * DT_NS, m.header.stamp)
            fill_pose(m.pose.pose, x, 0.0, 0.0)
            m.twist.twist.linear.x = v
            n = len(got)
            odom_pub.publish(m)
            assert spin_until(lambda: len(got) > n), f'no command at step {k}'
            v = got[-1][0]
            x += v * DT_NS * 1e-9
            xs.append(x)
            sent.append(monitor.heard[-1])
        stopped = xs[166:239]                       # 3.5-5 s: held at rest by the monitor
        assert max(stopped) - min(stopped) < 1e-9
        assert tracker.inputs.override.count >= 2 and not tracker.inputs.override.overridden
        assert max(sent) < 1.1 * CRUISE             # no wind-up while held, no leap after
        assert abs(xs[-1] - 4.0) < 0.02 and abs(got[-1][0]) < 0.02    # the plan's end, at rest
        assert all(abs(w) < 0.05 for _, w in got[:600])    # straight on (to the braking)
        assert any('overridden downstream' in kv.key and kv.value != '0'
                   for kv in _diagnostics(tracker))
    finally:
        ex.shutdown()
        for n in (base, monitor.node, tracker):
            n.destroy_node()
        rclpy.try_shutdown(context=ctx)


def _diagnostics(tracker):
    """The values of the tracker's next /diagnostics status (published to a capture)."""
    sent = []
    pub = tracker.pub_diag
    real = pub.publish
    pub.publish = sent.append
    try:
        tracker._diagnostics()
    finally:
        pub.publish = real
    return sent[0].status[0].values


def _plan(x0, length=4.0, offset=0.0):
    """A straight untimed plan along x from ``x0`` (5 cm apart), ``offset`` m to the left."""
    plan = Path()
    plan.header.frame_id = 'odom'
    for i in range(int(length / 0.05) + 1):
        ps = PoseStamped()
        fill_pose(ps.pose, x0 + 0.05 * i, offset, 0.0)
        plan.poses.append(ps)
    return plan


@pytest.mark.realtime
def test_a_plan_replaced_every_half_second_in_real_time_is_spliced_without_a_stop():
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=unique_domain_id('nav2_realtime'))
    tracker = TrackerNode(context=ctx, parameter_overrides=[Parameter(k, value=v) for k, v in {
        'K': K, 'mode': 'realtime', 'wait_for_trajectory': True, 'monitor': False,
        'cruise_speed': CRUISE, 'max_accel': 0.5}.items()])
    base = rclpy.create_node('base_and_planner', context=ctx)
    odom_pub = base.create_publisher(Odometry, topics.ODOM, DATA_QOS)
    plan_pub = base.create_publisher(Path, topics.TRAJECTORY, LATCHED_QOS)
    cmd = [0.0, 0.0]
    base.create_subscription(Twist, topics.CMD_VEL,
                             lambda m: cmd.__setitem__(slice(None), [m.linear.x, m.angular.z]),
                             DATA_QOS)
    state = {'x': 0.0, 'y': 0.0, 'th': 0.0, 'k': 0}
    speeds = []

    def tick():                       # the base at 50 Hz of wall clock, the planner at 2 Hz
        v, w = cmd
        state['x'] += v * math.cos(state['th']) * 0.02
        state['y'] += v * math.sin(state['th']) * 0.02
        state['th'] += w * 0.02
        k = state['k']
        if k == 0 or k % 25 == 0:     # from 0.2 m behind the robot, 2 mm to the side
            plan_pub.publish(_plan(max(state['x'] - 0.2, 0.0), 4.0 - state['x'],
                                   0.002 * (k // 25 % 2)))
        m = Odometry()
        m.header.frame_id = 'odom'
        m.header.stamp = base.get_clock().now().to_msg()
        fill_pose(m.pose.pose, state['x'], state['y'], state['th'])
        m.twist.twist.linear.x = v
        odom_pub.publish(m)
        speeds.append((k * 0.02, v))
        state['k'] += 1

    ex = make_executor(ctx)
    ex.add_node(tracker)
    ex.add_node(base)
    try:
        end = time.monotonic() + 5.0
        while not (odom_pub.get_subscription_count() and plan_pub.get_subscription_count()) \
                and time.monotonic() < end:
            ex.spin_once(timeout_sec=0.01)
        base.create_timer(0.02, tick)
        end = time.monotonic() + 5.0
        while time.monotonic() < end:
            ex.spin_once(timeout_sec=0.01)
        t, v = np.array(speeds).T
        assert tracker.inputs.splices >= 5 and tracker.inputs.rejected == 0
        driving = t > 1.5
        assert v[driving].min() > 0.75 * CRUISE and v.max() < 1.2 * CRUISE   # no stop, no lurch
        assert abs(state['y']) < 0.01 and state['x'] > 1.0
    finally:
        ex.shutdown()
        base.destroy_node()
        tracker.destroy_node()
        rclpy.try_shutdown(context=ctx)
