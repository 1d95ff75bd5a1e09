"""The tracker as a managed node, driven as a lifecycle manager does: lifecycle_msgs ChangeState
and GetState over DDS, each transition's effect on cmd_vel asserted with numbers; and a node
process with ``autostart: false`` brought up and shut down by a manager.

One tracker (``autostart: false``, lockstep, a straight untimed Path on ``trajectory``) and a
manager node in one process and one executor (the tracker's own, :func:`make_executor`); the
test is the plant: it integrates the commands of a unicycle and publishes the odometry.
"""
import math
import subprocess
import sys
import time

import pytest
import rclpy
from geometry_msgs.msg import PoseStamped, Twist
from lifecycle_msgs.msg import State, Transition
from lifecycle_msgs.srv import ChangeState, GetState
from nav_msgs.msg import Odometry, Path
from rcl_interfaces.srv import SetParameters
from rclpy.parameter import Parameter

from nonfragile_tracker.interface import topics
from nonfragile_tracker.control.simulation.gains import read_gain_file
from nonfragile_tracker.nodes.common import (DATA_QOS, LATCHED_QOS, fill_pose, make_executor,
                                             ns_to_stamp)
from nonfragile_tracker.nodes.tracker import TrackerNode

from conftest import CONFIG, unique_domain_id

DT_NS = 20_000_000                  # 50 Hz odometry
K = [float(v) for v in read_gain_file(CONFIG / 'tracker_gains.yaml').ravel()]


def _path(length=3.0, step=0.05):
    msg = Path()
    msg.header.frame_id = 'odom'
    for i in range(int(length / step) + 1):
        ps = PoseStamped()
        ps.header.frame_id = 'odom'
        fill_pose(ps.pose, i * step, 0.0, 0.0)
        msg.poses.append(ps)
    return msg


class Manager:
    """The manager's side: ChangeState/GetState clients, the plant's odometry, cmd_vel heard."""

    def __init__(self, context, tracker):
        self.tracker = tracker
        self.node = rclpy.create_node('manager', context=context)
        self.change = self.node.create_client(ChangeState, '/tracker/change_state')
        self.get = self.node.create_client(GetState, '/tracker/get_state')
        self.odom = self.node.create_publisher(Odometry, topics.ODOM, DATA_QOS)
        self.plan = self.node.create_publisher(Path, topics.TRAJECTORY, LATCHED_QOS)
        self.cmds = []
        self.node.create_subscription(Twist, topics.CMD_VEL,
                                      lambda m: self.cmds.append((m.linear.x, m.angular.z)),
                                      DATA_QOS)
        self.executor = make_executor(context)
        self.executor.add_node(tracker)
        self.executor.add_node(self.node)
        # the untimed plan's origin is the latest odometry stamp (lockstep), 0 before any:
        # starting at 0.2 s the plan is late and re-based to the first odometry it answers
        self.k = 10
        self.x = self.v = 0.0
        assert self.change.wait_for_service(5.0) and self.get.wait_for_service(5.0)

    def spin_until(self, done, timeout=5.0):
        end = time.monotonic() + timeout
        while not done() and time.monotonic() < end:
            self.executor.spin_once(timeout_sec=0.01)
        return done()

    def call(self, client, request):
        fut = client.call_async(request)
        assert self.spin_until(fut.done), 'no answer from the lifecycle service'
        return fut.result()

    def transition(self, tid):
        return self.call(self.change, ChangeState.Request(transition=Transition(id=tid))).success

    def state(self):
        return self.call(self.get, GetState.Request()).current_state.id

    def matched(self):
        """Wait until the tracker's cmd_vel and our odom have matched (or there is none)."""
        self.spin_until(lambda: self.node.count_publishers(topics.CMD_VEL) > 0
                        and (not self.tracker.active or self.odom.get_subscription_count() > 0),
                        timeout=3.0)

    def step(self, expect=True):
        """One odometry (the unicycle moved by the last command); the commands it got."""
        if self.cmds:
            self.v = self.cmds[-1][0]
        self.k += 1
        self.x += self.v * DT_NS * 1e-9
        m = Odometry()
        m.header.frame_id = 'odom'
        ns_to_stamp(self.k * DT_NS, m.header.stamp)
        fill_pose(m.pose.pose, self.x, 0.0, 0.0)
        m.twist.twist.linear.x = self.v
        n = len(self.cmds)
        self.odom.publish(m)
        if expect:
            assert self.spin_until(lambda: len(self.cmds) > n), f'no command for step {self.k}'
        else:                       # nothing may come: give it the time a command takes
            self.spin_until(lambda: len(self.cmds) > n, timeout=0.15)
        return self.cmds[n:]

    def close(self):
        self.executor.shutdown()
        self.node.destroy_node()


@pytest.fixture
def context():
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=unique_domain_id('lifecycle'))
    yield ctx
    rclpy.try_shutdown(context=ctx)


def managed(context, **params):
    values = {'K': K, 'autostart': False, 'mode': 'lockstep', 'wait_for_trajectory': True,
              'monitor': False, 'cruise_speed': 0.4, 'max_accel': 0.5, **params}
    return TrackerNode(context=context,
                       parameter_overrides=[Parameter(k, value=v) for k, v in values.items()])


def test_transitions_through_the_services_and_their_effect_on_cmd_vel(context):
    tracker = managed(context)
    mgr = Manager(context, tracker)
    try:
        mgr.plan.publish(_path())
        # unconfigured: no cmd_vel publisher, nothing commanded
        assert mgr.state() == State.PRIMARY_STATE_UNCONFIGURED
        assert mgr.node.count_publishers(topics.CMD_VEL) == 0
        assert mgr.step(expect=False) == []
        # a transition the state does not offer is refused, the node unchanged
        assert not mgr.transition(Transition.TRANSITION_ACTIVATE)
        assert mgr.state() == State.PRIMARY_STATE_UNCONFIGURED
        # configure -> inactive: cmd_vel exists, still nothing commanded
        assert mgr.transition(Transition.TRANSITION_CONFIGURE)
        assert mgr.state() == State.PRIMARY_STATE_INACTIVE
        mgr.matched()
        assert mgr.node.count_publishers(topics.CMD_VEL) == 1
        assert mgr.step(expect=False) == []
        # activate: the latched plan is taken, one command per odometry, speeding up
        assert mgr.transition(Transition.TRANSITION_ACTIVATE)
        assert mgr.state() == State.PRIMARY_STATE_ACTIVE
        mgr.matched()
        got = [mgr.step() for _ in range(40)]
        assert all(len(c) == 1 for c in got)
        v = [c[0][0] for c in got]
        assert v[0] == 0.0 and v[-1] > 0.15 and all(b >= a - 1e-9 for a, b in zip(v, v[1:]))
        assert max(abs(c[0][1]) for c in got) < 0.01, got          # a straight line: no turn
        assert 0.12 < mgr.x < 0.25             # 0.16 m: 0.5 m/s^2 for 0.8 s
        # deactivate: exactly one zero command, then silence
        n = len(mgr.cmds)
        assert mgr.transition(Transition.TRANSITION_DEACTIVATE)
        assert mgr.spin_until(lambda: len(mgr.cmds) > n)
        assert mgr.cmds[n:] == [(0.0, 0.0)]
        assert mgr.state() == State.PRIMARY_STATE_INACTIVE
        assert mgr.step(expect=False) == []
        assert mgr.step(expect=False) == []
        # activate again: a new run on the plan from the robot (at rest), commands resume
        assert mgr.transition(Transition.TRANSITION_ACTIVATE)
        again = [mgr.step() for _ in range(10)]
        assert all(len(c) == 1 for c in again)
        assert 0.0 < again[0][0][0] < 0.05 and again[-1][0][0] > again[0][0][0]
        # cleanup is not offered while active; deactivate (zero), cleanup: no cmd_vel left
        assert not mgr.transition(Transition.TRANSITION_CLEANUP)
        n = len(mgr.cmds)
        assert mgr.transition(Transition.TRANSITION_DEACTIVATE)
        assert mgr.spin_until(lambda: len(mgr.cmds) > n) and mgr.cmds[n:] == [(0.0, 0.0)]
        assert mgr.transition(Transition.TRANSITION_CLEANUP)
        assert mgr.state() == State.PRIMARY_STATE_UNCONFIGURED
        assert mgr.spin_until(lambda: mgr.node.count_publishers(topics.CMD_VEL) == 0)
        assert mgr.step(expect=False) == []
        # shutdown: finalized, and the node's process would end (run(): exit 0)
        assert mgr.transition(Transition.TRANSITION_UNCONFIGURED_SHUTDOWN)
        assert mgr.state() == State.PRIMARY_STATE_FINALIZED
        assert tracker.finished
    finally:
        mgr.close()
        tracker.destroy_node()


def test_configure_refusal_names_the_key_and_leaves_it_unconfigured(context):
    tracker = managed(context, K=[1.0] * 6)
    mgr = Manager(context, tracker)
    try:
        assert not mgr.transition(Transition.TRANSITION_CONFIGURE)
        assert mgr.state() == State.PRIMARY_STATE_UNCONFIGURED
        assert 'K' in tracker._refusal and 'has 6 entries' in tracker._refusal
        assert mgr.node.count_publishers(topics.CMD_VEL) == 0
        # unconfigured, a parameter set is taken (the configure validates): now it configures
        assert tracker.set_parameters([Parameter('K', value=K)])[0].successful
        assert mgr.transition(Transition.TRANSITION_CONFIGURE)
        assert mgr.state() == State.PRIMARY_STATE_INACTIVE
    finally:
        mgr.close()
        tracker.destroy_node()


def test_an_error_while_active_commands_zero_and_goes_through_error_processing(context):
    tracker = managed(context)
    mgr = Manager(context, tracker)
    try:
        mgr.plan.publish(_path())
        assert mgr.transition(Transition.TRANSITION_CONFIGURE)
        assert mgr.transition(Transition.TRANSITION_ACTIVATE)
        mgr.matched()
        moving = [mgr.step() for _ in range(30)]
        assert moving[-1][0][0] > 0.1

        def broken():
            raise RuntimeError('injected fault')
        tracker.inputs.compute = broken
        assert mgr.step() == [(0.0, 0.0)]           # the failing step's answer: zero
        assert mgr.spin_until(lambda: mgr.state() == State.PRIMARY_STATE_UNCONFIGURED)
        assert mgr.cmds[-1] == (0.0, 0.0)
        assert not tracker.configured and not tracker.active
        # and it can be brought up again by the manager
        assert mgr.transition(Transition.TRANSITION_CONFIGURE)
        assert mgr.transition(Transition.TRANSITION_ACTIVATE)
        mgr.matched()
        assert len(mgr.step()) == 1
        assert math.isfinite(mgr.cmds[-1][0])
    finally:
        mgr.close()
        tracker.destroy_node()


def test_shutdown_while_active_commands_zero(context):
    tracker = managed(context)
    mgr = Manager(context, tracker)
    try:
        mgr.plan.publish(_path())
        assert mgr.transition(Transition.TRANSITION_CONFIGURE)
        assert mgr.transition(Transition.TRANSITION_ACTIVATE)
        mgr.matched()
        assert [mgr.step() for _ in range(20)][-1][0][0] > 0.05
        n = len(mgr.cmds)
        assert mgr.transition(Transition.TRANSITION_ACTIVE_SHUTDOWN)
        assert mgr.spin_until(lambda: len(mgr.cmds) > n) and mgr.cmds[n:] == [(0.0, 0.0)]
        assert mgr.state() == State.PRIMARY_STATE_FINALIZED and tracker.finished
    finally:
        mgr.close()
        tracker.destroy_node()


def test_the_process_waits_for_its_manager_and_ends_on_shutdown(tmp_path, ros_env):
    """``autostart: false`` in a node process: a bad gain does not end it (exit 2 is for
    autostart); the manager's configure is refused, a good gain set, configure, activate and
    shutdown end the process with 0 and no traceback."""
    params = tmp_path / 'tracker.yaml'
    params.write_text('tracker:\n  ros__parameters:\n    autostart: false\n'
                      '    K: [1.0, 1.0, 1.0]\n    monitor: false\n')
    proc = subprocess.Popen([sys.executable, '-m', 'nonfragile_tracker.nodes.entry', 'tracker',
                             '--ros-args', '--params-file', str(params)], env=ros_env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=int(ros_env['ROS_DOMAIN_ID']))
    node = rclpy.create_node('manager', context=ctx)
    try:
        change = node.create_client(ChangeState, '/tracker/change_state')
        get = node.create_client(GetState, '/tracker/get_state')
        setp = node.create_client(SetParameters, '/tracker/set_parameters')
        assert change.wait_for_service(30.0) and get.wait_for_service(5.0)

        ex = rclpy.executors.SingleThreadedExecutor(context=ctx)
        ex.add_node(node)

        def call(client, req):
            fut = client.call_async(req)
            ex.spin_until_future_complete(fut, timeout_sec=10.0)
            assert fut.done()
            return fut.result()

        def transition(tid):
            return call(change, ChangeState.Request(transition=Transition(id=tid))).success
        assert call(get, GetState.Request()).current_state.id == State.PRIMARY_STATE_UNCONFIGURED
        assert not transition(Transition.TRANSITION_CONFIGURE)     # K refused: still running
        assert proc.poll() is None
        assert setp.wait_for_service(5.0)
        res = call(setp, SetParameters.Request(parameters=[
            Parameter('K', value=K).to_parameter_msg()]))
        assert res.results[0].successful
        assert transition(Transition.TRANSITION_CONFIGURE)
        assert transition(Transition.TRANSITION_ACTIVATE)
        assert transition(Transition.TRANSITION_ACTIVE_SHUTDOWN)
        out, err = proc.communicate(timeout=20)
        assert proc.returncode == 0, err
        assert 'configure refused: tracker: K has 3 entries' in err and 'Traceback' not in err
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)
