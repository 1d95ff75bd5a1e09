"""Trajectories through the nodes: a CSV lap and a nav_msgs/Path from the test are
tracked in lockstep equal to the in-process simulation; bad trajectories are refused
and the previous one stays."""
import math
import os
import subprocess
import sys

import numpy as np
import pytest

from nonfragile_tracker.control.simulation.follow import simulate_following
from nonfragile_tracker.control.simulation.gains import read_gain_file
from nonfragile_tracker.control.simulation.tracker import TrackerConfig
from nonfragile_tracker.control.simulation.trajectory import load_waypoints
from nonfragile_tracker.interface.scenario import paper_plant_config

from conftest import CONFIG, ROOT, unique_domain_id

pytestmark = pytest.mark.ros

LAP = CONFIG / 'trajectories' / 'lap.csv'
DURATION = 16.0
POSE0 = [0.0, -0.02, 0.0]
#: The paper's ideal plant in lockstep: the max-decay design (the lap's bias bound below is
#: pinned to it; the shipped default is checked on real bases).
GAINS = CONFIG / 'max_decay_gains.yaml'


def scenario(**reference):
    from nonfragile_tracker.workflows.runner import scenario_parameters
    ov = {'plant': {'ros__parameters': {'duration': DURATION, 'initial_pose': POSE0,
                                        'initial_speed': 0.0}},
          'reference': {'ros__parameters': reference},
          'tracker': {'ros__parameters': {'wait_for_trajectory': True}}}
    return scenario_parameters(CONFIG / 'paper_scenario.yaml', GAINS, ov)


def simulation(traj, origin_ns=0):
    K = read_gain_file(GAINS)
    pc = paper_plant_config(x0=POSE0[0], y0=POSE0[1], th0=POSE0[2], v0=0.0)
    tc = TrackerConfig(K=K, A_tau=pc.A_tau, tau=pc.tau)
    return simulate_following(pc, tc, traj, int(round(DURATION / pc.dt)), origin_ns=origin_ns)


def as_sent(traj, origin_ns=0):
    """The trajectory the tracker builds from the Path the reference publishes."""
    from nonfragile_tracker.nodes.trajectory_io import path_to_trajectory, trajectory_to_path
    msg = trajectory_to_path(traj, origin_ns, 'odom')
    return path_to_trajectory(msg, frame='odom', source='test')[0], msg


@pytest.mark.parametrize('stamped', [False, True])
def test_csv_lap_through_the_nodes_equals_the_simulation(tmp_path, stamped):
    """The lap through the nodes (recorded; with TwistStamped commands too)."""
    from nonfragile_tracker.bag.reader import read_bag
    from nonfragile_tracker.workflows.runner import run_composed
    params = scenario(trajectory_file=str(LAP))
    if stamped:
        for node in ('tracker', 'plant', 'recorder'):
            params.setdefault(node, {'ros__parameters': {}})['ros__parameters'][
                'enable_stamped_cmd_vel'] = True
    res = run_composed(params, tmp_path)
    assert all(c == 0 for c in res.exit_codes.values()), res.exit_codes
    bag = read_bag(res.bag)
    assert bag.msgtypes['/cmd_vel'] == ('geometry_msgs/msg/TwistStamped' if stamped
                                        else 'geometry_msgs/msg/Twist')
    assert bag.counts['/trajectory'] == 1 and bag.counts['/reference/path'] == 1
    run = bag.run
    traj, _ = as_sent(load_waypoints(LAP))
    sim = simulation(traj)
    steps = int(round(DURATION / 0.01))
    assert len(run.pose) == steps + 1 and len(run.commands) == steps + 1
    np.testing.assert_allclose(run.pose.x, sim.x, rtol=0, atol=1e-9)
    np.testing.assert_allclose(run.pose.y, sim.y, rtol=0, atol=1e-9)
    np.testing.assert_allclose(run.commands.v, sim.cmd_v, rtol=0, atol=1e-9)
    np.testing.assert_allclose(run.commands.w, sim.cmd_w, rtol=0, atol=1e-9)
    np.testing.assert_allclose(run.reference.x, sim.xd, rtol=0, atol=1e-12)
    # the lap is followed (A_tau's bias stays in mm) and the robot ends at rest
    err = np.hypot(run.pose.x - run.reference.x, run.pose.y - run.reference.y)
    assert err[run.pose.t > 5.0].max() < 0.03
    assert run.commands.v[-1] == 0.0 and run.commands.w[-1] == 0.0
    assert 0.45 < np.max(np.abs(run.commands.v)) < 0.6
    if not stamped:
        # the report says which errors are the tracking (trajectory active) and which the
        # rest after its end
        from nonfragile_tracker.bag.report import bag_report, format_report
        rep = bag_report(res.bag, plots=False)
        ph = rep.phases
        active = (sim.t >= traj.t_start) & (sim.t <= traj.t_end)
        assert ph.active_samples == int(active.sum())
        assert ph.active_span == pytest.approx((0.0, traj.t_end), abs=0.011)
        assert ph.active_rms == pytest.approx(math.sqrt(np.mean(err[active] ** 2)), rel=1e-9)
        assert ph.active_max == pytest.approx(err[active].max(), rel=1e-9)
        assert ph.after_samples == int((sim.t > traj.t_end).sum())
        assert ph.after_final == pytest.approx(err[-1], rel=1e-9)
        text = format_report(rep)
        assert 'while the trajectory is active (0.00..13.00 s): RMS / max' in text
        assert 'after its end (at rest)' in text and 'final position error (whole run)' in text


def spin_nodes(nodes, done, ctx, timeout=60.0):
    import time
    from nonfragile_tracker.nodes.common import make_executor
    ex = make_executor(ctx)
    for n in nodes:
        ex.add_node(n)
    deadline = time.monotonic() + timeout
    while ctx.ok() and not done() and time.monotonic() < deadline:
        ex.spin_once(timeout_sec=0.02)
    for n in nodes:
        ex.remove_node(n)


def param_list(params, node, **extra):
    from rclpy.parameter import Parameter
    vals = dict(params[node]['ros__parameters'])
    vals.update(extra)
    return [Parameter(k, value=v) for k, v in vals.items()]


@pytest.fixture
def ros_context():
    import rclpy
    ctx = rclpy.Context()
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    rclpy.init(context=ctx, domain_id=unique_domain_id('trajnodes'))
    yield ctx
    rclpy.try_shutdown(context=ctx)


def test_path_from_a_topic_is_tracked_and_bad_ones_are_refused(ros_context):
    """A Path published by the test: tracker (lockstep) follows it; a bad Path later is
    refused with the reason and the run goes on with the previous trajectory."""
    from nav_msgs.msg import Odometry, Path as PathMsg
    from geometry_msgs.msg import Twist
    from rclpy.node import Node
    from nonfragile_tracker.nodes.common import DATA_QOS, LATCHED_QOS
    from nonfragile_tracker.nodes.plant import PlantNode
    from nonfragile_tracker.nodes.tracker import TrackerNode
    from nonfragile_tracker.control.simulation.trajectory import from_waypoints

    ctx = ros_context
    # an S-curve with stamps from 1.0 s (origin): 4 s of motion, rest at both ends
    t = np.linspace(0.0, 8.0, 17)
    traj0 = from_waypoints(t, 0.05 * t * t * (3 - t / 4) / 4, 0.3 * np.sin(t / 8 * math.pi),
                           source='test')
    origin = 1_000_000_000
    traj, msg = as_sent(traj0, origin)

    params = scenario()
    test = Node('test_publisher', context=ctx)
    pub = test.create_publisher(PathMsg, 'trajectory', LATCHED_QOS)
    odoms, cmds = [], []
    test.create_subscription(Odometry, 'odom', lambda m: odoms.append(
        (m.header.stamp.sec * 10**9 + m.header.stamp.nanosec, m.pose.pose.position.x,
         m.pose.pose.position.y)), DATA_QOS)
    test.create_subscription(Twist, 'cmd_vel', lambda m: cmds.append((m.linear.x, m.angular.z)),
                             DATA_QOS)
    pub.publish(msg)
    # the test's publisher is the trajectory source (no reference node: it would publish
    # its built-in path as a second trajectory)
    tracker = TrackerNode(context=ctx, parameter_overrides=param_list(params, 'tracker'))
    spin_nodes([test, tracker], lambda: tracker.inputs.follower is not None, ctx)
    assert tracker.inputs.follower is not None and tracker.inputs.origin_ns == origin
    plant = PlantNode(context=ctx, parameter_overrides=param_list(
        params, 'plant', lockstep_subscribers=2))
    nodes = [test, tracker, plant]
    sent_bad = []

    def done():
        if len(odoms) > 500 and not sent_bad:       # mid-run: a Path in the wrong frame
            bad = PathMsg()
            bad.header = msg.header
            bad.header.frame_id = 'map'
            bad.poses = list(msg.poses)
            pub.publish(bad)
            sent_bad.append(True)
        return plant.finished

    spin_nodes(nodes, done, ctx)
    try:
        assert plant.finished and plant.exit_code == 0
        steps = int(round(DURATION / 0.01))
        sim = simulation(traj, origin)
        x = np.array([o[1] for o in odoms])
        y = np.array([o[2] for o in odoms])
        assert len(x) == steps + 1 and len(cmds) == steps + 1
        np.testing.assert_allclose(x, sim.x, rtol=0, atol=1e-9)
        np.testing.assert_allclose(y, sim.y, rtol=0, atol=1e-9)
        np.testing.assert_allclose([c[0] for c in cmds], sim.cmd_v, rtol=0, atol=1e-9)
        np.testing.assert_allclose([c[1] for c in cmds], sim.cmd_w, rtol=0, atol=1e-9)
        assert tracker.inputs.rejected >= 1                 # the wrong-frame Path was refused
        assert tracker.inputs.follower.trajectory is not None and tracker.inputs.follower.finished
        # at rest after the end: zero commands from the step it stopped (the paper's
        # A_tau xi(t - tau) term then lets the plant drift; no command can hold it there)
        f = tracker.inputs.follower
        k_end = int(round(f.finished_at / 0.01)) + origin // 10_000_000
        end = traj.sample(traj.t_end)
        assert f.finished_at - traj.t_end < 0.5
        assert math.hypot(x[k_end] - end.x, y[k_end] - end.y) < 0.02
        assert all(c == (0.0, 0.0) for c in cmds[k_end:])
        assert np.all(np.abs(sim.cmd_v[k_end:]) == 0.0)
    finally:
        for n in nodes:
            n.destroy_node()


def test_bad_trajectory_file_refused_by_the_node(tmp_path):
    bad = tmp_path / 'bad.csv'
    bad.write_text('t,x,y\n0,0,0\n1,1,0\n0.5,2,0\n')
    env = dict(os.environ, ROS_DOMAIN_ID=str(unique_domain_id('trajbad')),
               PYTHONPATH=str(ROOT))
    p = subprocess.run([sys.executable, '-m', 'nonfragile_tracker.nodes.reference', '--ros-args',
                        '-p', f'trajectory_file:={bad}'], capture_output=True, text=True,
                       env=env, timeout=60)
    assert p.returncode == 2
    assert f'{bad}: point 2: time t = 0.5 s is not after' in p.stderr
    assert 'Traceback' not in p.stderr



@pytest.mark.parametrize('stamped', [True, False])
def test_twist_and_twist_stamped_both_move_the_plant(ros_context, stamped):
    """cmd_vel as TwistStamped (diff_drive_controller since Jazzy) or Twist: the same run;
    the stamped header carries the command time (the odom stamp it answers) and the body
    frame.  Tracking error, travelled path, marker and diagnostics are published."""
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import Twist, TwistStamped, Vector3Stamped
    from nav_msgs.msg import Odometry, Path as PathMsg
    from rclpy.node import Node
    from visualization_msgs.msg import Marker
    from nonfragile_tracker.control.simulation.follow import path_errors
    from nonfragile_tracker.control.simulation.reference import circle
    from nonfragile_tracker.control.simulation.simulate import simulate_tracking
    from nonfragile_tracker.nodes.common import DATA_QOS
    from nonfragile_tracker.nodes.plant import PlantNode
    from nonfragile_tracker.nodes.reference import ReferenceNode
    from nonfragile_tracker.nodes.tracker import TrackerNode
    from nonfragile_tracker.workflows.runner import scenario_parameters

    ctx = ros_context
    duration = 3.0
    params = scenario_parameters(CONFIG / 'paper_scenario.yaml', CONFIG / 'tracker_gains.yaml',
                                 {'plant': {'ros__parameters': {'duration': duration}}})
    flag = {'enable_stamped_cmd_vel': stamped}
    got = {'cmd': [], 'odom': [], 'err': [], 'path': [], 'marker': [], 'diag': []}
    test = Node('test_listener', context=ctx)
    ctype = TwistStamped if stamped else Twist
    test.create_subscription(ctype, 'cmd_vel', got['cmd'].append, DATA_QOS)
    test.create_subscription(Odometry, 'odom', got['odom'].append, DATA_QOS)
    test.create_subscription(Vector3Stamped, 'tracker/error', got['err'].append, DATA_QOS)
    test.create_subscription(PathMsg, 'tracker/path', got['path'].append, DATA_QOS)
    test.create_subscription(Marker, 'tracker/reference_marker', got['marker'].append, DATA_QOS)
    test.create_subscription(DiagnosticArray, '/diagnostics', got['diag'].append, DATA_QOS)
    tracker = TrackerNode(context=ctx, parameter_overrides=param_list(
        params, 'tracker', diagnostics_period=0.5, **flag))
    reference = ReferenceNode(context=ctx, parameter_overrides=param_list(params, 'reference'))
    plant = PlantNode(context=ctx, parameter_overrides=param_list(
        params, 'plant', lockstep_subscribers=2, **flag))
    nodes = [test, tracker, reference, plant]
    steps = int(round(duration / 0.01))
    spin_nodes(nodes, lambda: plant.finished and len(got['err']) > steps
               and len(got['cmd']) > steps and got['path']
               and len(got['path'][-1].poses) == 16, ctx, timeout=30.0)
    try:
        assert plant.finished and plant.exit_code == 0
        steps = int(round(duration / 0.01))
        K = read_gain_file(CONFIG / 'tracker_gains.yaml')
        pc = paper_plant_config()
        sim = simulate_tracking(pc, TrackerConfig(K=K, A_tau=pc.A_tau, tau=pc.tau), circle(),
                                steps)
        odom_x = np.array([m.pose.pose.position.x for m in got['odom']])
        np.testing.assert_allclose(odom_x, sim.x, rtol=0, atol=1e-9)    # the plant moved so
        assert abs(sim.x[-1] - sim.x[0]) > 0.1
        twists = [m.twist if stamped else m for m in got['cmd']]
        np.testing.assert_allclose([t.angular.z for t in twists], sim.cmd_w, rtol=0, atol=1e-9)
        if stamped:
            assert all(m.header.frame_id == 'base_link' for m in got['cmd'])
            stamps = [m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for m in got['cmd']]
            assert stamps == [k * 10_000_000 for k in range(steps + 1)]   # command time
        # tracking error: along/cross-track and heading against the reference point
        assert len(got['err']) == steps + 1
        ref = circle().sample(1.5)
        e = got['err'][150].vector
        assert (e.x, e.y, e.z) == pytest.approx(path_errors(sim.x[150], sim.y[150],
                                                            sim.th[150], ref), abs=1e-9)
        assert got['err'][0].vector.y == pytest.approx(path_errors(
            0.7, 0.1, math.pi / 2, circle().sample(0.0))[1], abs=1e-12)
        assert len(got['path'][-1].poses) == 16 and got['path'][-1].header.frame_id == 'odom'
        assert got['marker'] and got['marker'][-1].type == Marker.ARROW
        status = got['diag'][-1].status[0]
        values = {kv.key: kv.value for kv in status.values}
        assert 100 < int(values['commands']) <= steps + 1      # sent every 0.5 s (sim time)
        assert values['rejected inputs'] == '0' and values['deadline misses'] == '0'
        assert float(values['loop period (s)']) == pytest.approx(0.01)
        assert 'following the trajectory' in status.message   # the circle as knots
    finally:
        for n in nodes:
            n.destroy_node()


def bad_paths(good):
    """One bad nav_msgs/Path per class, with the text the refusal must contain."""
    from copy import deepcopy
    out = []
    few = deepcopy(good)
    few.poses = few.poses[1:2]
    out.append((few, '1 point(s); a trajectory needs at least 2'))
    order = deepcopy(good)
    order.poses[3].header.stamp = deepcopy(order.poses[1].header.stamp)
    out.append((order, 'point 3: time t = 0.5 s is not after'))
    nan = deepcopy(good)
    nan.poses[2].pose.position.y = math.nan
    out.append((nan, 'point 2: y = nan is not finite'))
    frame = deepcopy(good)
    frame.header.frame_id = 'map'
    out.append((frame, "frame_id 'map'"))
    pose_frame = deepcopy(good)
    pose_frame.poses[4].header.frame_id = 'base_link'
    out.append((pose_frame, "point 4: frame_id 'base_link'"))
    quat = deepcopy(good)
    quat.poses[5].pose.orientation.w = 3.0
    out.append((quat, 'point 5: orientation'))
    return out


def test_bad_paths_and_multidof_through_the_tracker(ros_context):
    """Every bad class is refused with its reason naming the topic, the point and the
    value; the tracker keeps its trajectory; a MultiDOFJointTrajectory with velocities
    and accelerations replaces it (a new run)."""
    from geometry_msgs.msg import Transform, Twist as TwistMsg
    from nav_msgs.msg import Path as PathMsg
    from rclpy.node import Node
    from trajectory_msgs.msg import MultiDOFJointTrajectory, MultiDOFJointTrajectoryPoint
    from nonfragile_tracker.control.simulation.trajectory import from_waypoints
    from nonfragile_tracker.nodes.common import LATCHED_QOS
    from nonfragile_tracker.nodes.tracker import TrackerNode

    ctx = ros_context
    t = np.linspace(0.0, 4.0, 9)
    traj0 = from_waypoints(t, 0.1 * t, 0.0 * t)
    _, good = as_sent(traj0)
    params = scenario()
    test = Node('test_bad_paths', context=ctx)
    pub = test.create_publisher(PathMsg, 'trajectory', LATCHED_QOS)
    pub_m = test.create_publisher(MultiDOFJointTrajectory, 'trajectory_multidof', LATCHED_QOS)
    # retime off: the MultiDOF trajectory below ends at 2 m/s, above the default
    # max_linear_speed, and is checked here for its exact conversion (not its re-timing)
    tracker = TrackerNode(context=ctx, parameter_overrides=param_list(params, 'tracker',
                                                                     retime=False))
    try:
        pub.publish(good)
        spin_nodes([test, tracker], lambda: tracker.inputs.follower is not None, ctx, timeout=20)
        kept = tracker.inputs.follower.trajectory
        for msg, needle in bad_paths(good):
            before = tracker.inputs.rejected
            pub.publish(msg)
            spin_nodes([test, tracker], lambda: tracker.inputs.rejected > before, ctx, timeout=10)
            assert tracker.inputs.rejected == before + 1, needle
            assert tracker.inputs.last_refusal.startswith('topic /trajectory: ')
            assert needle in tracker.inputs.last_refusal
            assert tracker.inputs.follower.trajectory is kept
        m = MultiDOFJointTrajectory()
        m.header.frame_id = 'odom'
        m.joint_names = ['base_link']
        for k, tk in enumerate([0.0, 1.0, 2.0]):
            p = MultiDOFJointTrajectoryPoint()
            tr = Transform()
            tr.translation.x, tr.rotation.w = 0.5 * tk * tk, 1.0
            v, a = TwistMsg(), TwistMsg()
            v.linear.x, a.linear.x = 1.0 * tk, 1.0
            p.transforms, p.velocities, p.accelerations = [tr], [v], [a]
            p.time_from_start.sec = int(tk)
            m.points.append(p)
        pub_m.publish(m)
        spin_nodes([test, tracker], lambda: tracker.inputs.follower.trajectory is not kept, ctx,
                   timeout=10)
        new = tracker.inputs.follower.trajectory
        assert new.kind == 'quintic Hermite'
        s = new.sample(1.5)                          # x = t^2 / 2 exactly
        assert (s.x, s.vx, s.ax) == pytest.approx((1.125, 1.5, 1.0), abs=1e-12)
        m.points[2].transforms[0].translation.y = math.inf
        before = tracker.inputs.rejected
        pub_m.publish(m)
        spin_nodes([test, tracker], lambda: tracker.inputs.rejected > before, ctx, timeout=10)
        assert 'topic /trajectory_multidof: point 2: y = inf' in tracker.inputs.last_refusal
        assert tracker.inputs.follower.trajectory is new
    finally:
        tracker.destroy_node()
        test.destroy_node()


@pytest.mark.realtime
def test_path_tracked_in_real_time(ros_context):
    """Real time (wall clock, timers): the tracker samples the Path at each odom stamp
    without reference samples; the errors stay within those of the simulation of the
    same trajectory (timer jitter under load allowed for)."""
    import time
    from nav_msgs.msg import Odometry, Path as PathMsg
    from rclpy.node import Node
    from nonfragile_tracker.control.simulation.trajectory import from_waypoints
    from nonfragile_tracker.nodes.common import DATA_QOS, LATCHED_QOS
    from nonfragile_tracker.nodes.plant import PlantNode
    from nonfragile_tracker.nodes.tracker import TrackerNode

    ctx = ros_context
    t = np.linspace(0.0, 4.0, 9)
    traj0 = from_waypoints(t, 0.1 * t * t * (3 - t / 2) / 4, 0.2 * np.sin(t / 4 * math.pi))
    params = scenario()
    rt = {'mode': 'realtime'}
    test = Node('test_rt', context=ctx)
    pub = test.create_publisher(PathMsg, 'trajectory', LATCHED_QOS)
    odoms = []
    test.create_subscription(Odometry, 'odom', lambda m: odoms.append(
        (m.header.stamp.sec * 10**9 + m.header.stamp.nanosec, m.pose.pose.position.x,
         m.pose.pose.position.y)), DATA_QOS)
    tracker = TrackerNode(context=ctx, parameter_overrides=param_list(params, 'tracker', **rt))
    s0 = traj0.sample(0.0)                              # the robot waits at the start
    pose0 = [s0.x, s0.y, s0.heading]
    plant = PlantNode(context=ctx, parameter_overrides=param_list(
        params, 'plant', duration=0.0, tau=0.0, initial_pose=pose0, **rt))   # until stopped
    nodes = [test, tracker, plant]
    try:
        # the robot is up and its odometry reaches the tracker: start in 0.5 s (wall clock)
        spin_nodes(nodes, lambda: tracker.inputs.last_odom_stamp >= 0 and len(odoms) > 5, ctx,
                   timeout=30)
        origin = time.time_ns() + 500_000_000
        traj, msg = as_sent(traj0, origin)
        pub.publish(msg)
        spin_nodes(nodes, lambda: tracker.inputs.follower is not None and tracker.inputs.follower.finished
                   and time.time_ns() > origin + 5_500_000_000, ctx, timeout=30)
        assert tracker.inputs.follower.finished
        st = np.array([o[0] for o in odoms], dtype=np.int64)
        tt = (st - origin) * 1e-9
        ref = traj.evaluate(tt)
        err = np.hypot(np.array([o[1] for o in odoms]) - ref.x,
                       np.array([o[2] for o in odoms]) - ref.y)
        moving = (tt > 0.0) & (tt < traj.t_end)
        assert moving.sum() > 200                      # the run covered the trajectory
        K = read_gain_file(CONFIG / 'tracker_gains.yaml')
        pc = paper_plant_config(x0=pose0[0], y0=pose0[1], th0=pose0[2], v0=0.0, tau=0.0)
        sim = simulate_following(pc, TrackerConfig(K=K, A_tau=pc.A_tau, tau=pc.tau), traj,
                                 650, origin_ns=1_000_000_000)   # starts at t = 1 s
        print(f'{moving.sum()} odom samples during the trajectory')
        sim_err = sim.error[(sim.t > 1.0) & (sim.t < 1.0 + traj.t_end)]
        rms = math.sqrt(np.mean(err[moving] ** 2))
        print(f'real time: RMS {rms:.5f} m, max {err[moving].max():.5f} m, final {err[-1]:.5f} m; '
              f'simulation: RMS {math.sqrt(np.mean(sim_err ** 2)):.5f} m, max {sim_err.max():.5f} m')
        sim_rms = math.sqrt(np.mean(sim_err ** 2))
        # The wall-clock plant integrates dt per timer tick; a missed tick (machine under
        # load) is lost motion against the stamps, which the tracker must catch up.
        # With the 100 Hz timer kept the errors are the simulation's; with ticks missed
        # the trajectory is still followed within a few cm.
        ticks_kept = moving.sum() / (traj.t_end / 0.01)
        if ticks_kept > 0.98:
            assert rms < sim_rms + 0.005 and err[moving].max() < sim_err.max() + 0.01
        assert rms < sim_rms + 0.05 and err[moving].max() < sim_err.max() + 0.1
        assert err[-1] < 0.02
    finally:
        for n in nodes:
            n.destroy_node()


def test_reference_relays_an_untimed_plan(ros_context):
    """A planner's Path without stamps, relayed by the reference: the tracker gets it
    with the time law (cruise speed, acceleration limit) and the reference's start time;
    a bad plan is refused by the reference and nothing changes downstream."""
    from nav_msgs.msg import Path as PathMsg
    from geometry_msgs.msg import PoseStamped
    from rclpy.node import Node
    from nonfragile_tracker.control.simulation.trajectory import time_law
    from nonfragile_tracker.nodes.reference import ReferenceNode
    from nonfragile_tracker.nodes.tracker import TrackerNode

    ctx = ros_context
    params = scenario(trajectory_topic='plan', cruise_speed=0.4, max_accel=0.2)
    test = Node('test_planner', context=ctx)
    pub = test.create_publisher(PathMsg, 'plan', 10)
    tracker = TrackerNode(context=ctx, parameter_overrides=param_list(params, 'tracker'))
    reference = ReferenceNode(context=ctx, parameter_overrides=param_list(params, 'reference'))
    nodes = [test, tracker, reference]
    try:
        spin_nodes(nodes, lambda: pub.get_subscription_count() >= 1, ctx, timeout=20)
        plan = PathMsg()
        plan.header.frame_id = 'odom'
        xs = [0.0, 1.0, 2.0, 2.0]
        ys = [0.0, 0.0, 0.5, 1.5]
        for x, y in zip(xs, ys):
            ps = PoseStamped()
            ps.pose.position.x, ps.pose.position.y, ps.pose.orientation.w = x, y, 1.0
            plan.poses.append(ps)
        pub.publish(plan)
        spin_nodes(nodes, lambda: tracker.inputs.follower is not None, ctx, timeout=20)
        traj = tracker.inputs.follower.trajectory
        assert traj.t_end == pytest.approx(time_law(xs, ys, 0.4, 0.2)[-1], abs=1e-9)
        assert tracker.inputs.origin_ns == reference.origin_ns
        s = traj.sample(traj.t_end / 2)
        assert 0.2 < math.hypot(s.vx, s.vy) < 0.5
        bad = PathMsg()
        bad.header.frame_id = 'odom'
        bad.poses = list(plan.poses)
        bad.poses[1] = PoseStamped()
        bad.poses[1].pose.position.x = math.nan
        bad.poses[1].pose.orientation.w = 1.0
        pub.publish(bad)
        spin_nodes(nodes, lambda: reference.last_refusal, ctx, timeout=10)
        assert reference.last_refusal == 'topic plan: point 1: x = nan is not finite; every ' \
            'value must be a finite number'
        spin_nodes(nodes, lambda: False, ctx, timeout=0.3)
        assert tracker.inputs.follower.trajectory is traj and tracker.inputs.rejected == 0
    finally:
        for n in nodes:
            n.destroy_node()


@pytest.mark.realtime
def test_reference_started_5_s_before_the_tracker_does_not_make_it_chase(ros_context):
    """Real time: the reference node publishes the lap 5 s before the tracker starts; the
    tracker re-bases it, so its first second's commanded speed stays within 10 % of the
    lap's own speed profile (before: a lurch after a reference already 5 s ahead)."""
    import time
    from geometry_msgs.msg import Twist
    from rclpy.node import Node
    from nonfragile_tracker.nodes.common import DATA_QOS
    from nonfragile_tracker.nodes.plant import PlantNode
    from nonfragile_tracker.nodes.reference import ReferenceNode
    from nonfragile_tracker.nodes.tracker import TrackerNode

    ctx = ros_context
    params = scenario(trajectory_file=str(LAP))
    rt = {'mode': 'realtime'}
    reference = ReferenceNode(context=ctx, parameter_overrides=param_list(
        params, 'reference', publish_samples=False, **rt))
    spin_nodes([reference], lambda: False, ctx, timeout=5.0)      # 5 s alone: the lap runs
    test = Node('test_late', context=ctx)
    cmds = []
    test.create_subscription(Twist, 'cmd_vel', lambda m: cmds.append(
        (time.monotonic(), m.linear.x)), DATA_QOS)
    tracker = TrackerNode(context=ctx, parameter_overrides=param_list(params, 'tracker', **rt))
    plant = PlantNode(context=ctx, parameter_overrides=param_list(
        params, 'plant', duration=0.0, tau=0.0, initial_pose=[0.0, 0.0, 0.0], **rt))
    nodes = [reference, test, tracker, plant]
    try:
        moving = []
        spin_nodes(nodes, lambda: bool(moving.extend(c for c in cmds[len(moving):]
                                                     if c[1] != 0.0 or moving)
                                       or (moving and moving[-1][0] - moving[0][0] > 1.5)),
                   ctx, timeout=30)
        f = tracker.inputs.follower
        assert f is not None and f.started and f.refused is None
        assert f.offset > 4.0                   # re-based: the lap was 5 s old
        t0 = moving[0][0]
        first = np.array([v for t, v in moving if t - t0 <= 1.0])
        prof = load_waypoints(LAP).evaluate(np.linspace(0.0, 1.1, 221))
        peak = float(np.hypot(prof.vx, prof.vy).max())
        print(f'first second: max |cmd v| {np.abs(first).max():.3f} m/s, profile peak '
              f'{peak:.3f} m/s (re-based by {f.offset:.3f} s)')
        assert first.size > 50 and float(np.abs(first).max()) <= 1.1 * peak
    finally:
        for n in nodes:
            n.destroy_node()


def test_tracker_checks_each_limit_and_retimes_or_refuses(ros_context):
    """The line-arc lap to trackers with one limit below its peak each: the log/diagnostics
    note names the limit, the time and the value, and the tracker follows the re-timed lap;
    a minimum turning radius above the lap's is a refusal naming place and curvature."""
    from nav_msgs.msg import Path as PathMsg
    from rclpy.node import Node
    from nonfragile_tracker.control.simulation.limits import (ACCEL_FRACTION, TOLERANCE, Limits,
                                                              check)
    from nonfragile_tracker.nodes.common import LATCHED_QOS
    from nonfragile_tracker.nodes.tracker import TrackerNode

    ctx = ros_context
    lap = load_waypoints(CONFIG / 'trajectories' / 'line_arc_lap.csv')
    _, msg = as_sent(lap)
    params = scenario()
    test = Node('test_limits', context=ctx)
    pub = test.create_publisher(PathMsg, 'trajectory', LATCHED_QOS)
    pub.publish(msg)
    for name, value in (('max_linear_speed', 0.3), ('max_linear_accel', 0.3),
                        ('max_angular_speed', 0.9), ('max_angular_accel', 3.0),
                        ('min_turning_radius', 0.5)):
        tracker = TrackerNode(context=ctx, parameter_overrides=param_list(
            params, 'tracker', **{name: value}))
        try:
            spin_nodes([test, tracker], lambda: tracker.inputs.follower is not None
                       or tracker.inputs.last_refusal, ctx, timeout=30)
            # a trajectory may use ACCEL_FRACTION of an acceleration limit (the rest is the
            # feedback's): it is checked and re-timed against that share, to the re-timing's
            # accuracy (TOLERANCE), and the note says so
            share = Limits(**{name: value}).accel_share(ACCEL_FRACTION)
            v = check(lap, share, tolerance=TOLERANCE)[name]
            value = getattr(share, name)
            if name == 'min_turning_radius':
                assert tracker.inputs.follower is None
                note = tracker.inputs.last_refusal
                assert 'min_turning_radius = 0.5 m' in note and 'curvature' in note
            else:
                note = tracker.last_retime
                # re-timed: slower than planned
                assert tracker.inputs.follower.trajectory.source.endswith('(re-timed)')
                assert tracker.inputs.follower.trajectory.t_end > lap.t_end
                assert f'{v.violated_value:.4g}' in note
                assert ('the acceleration limits at 80 % (trajectory_accel_fraction' in note) \
                    == name.endswith('_accel')
            assert f'VIOLATES {name} = {value:g}' in note or name == 'min_turning_radius'
            if name == 'min_turning_radius':     # the fitted path's place and planned time
                assert 'first above the limit at t = ' in note and ' at (' in note
            else:
                assert f'{v.violated_at:.3f} s' in note
        finally:
            tracker.destroy_node()
    test.destroy_node()


@pytest.mark.parametrize('record_all', [False, True])
def test_replay_reproduces_a_waypoint_run_with_predictor_and_retiming(tmp_path, record_all):
    """bag replay of a lockstep run that followed a waypoint file (re-timed within the
    base's limits) with the latency predictor from a latency-design style gain file:
    the commands are reproduced exactly, from a lean and from a full recording (the
    trajectory message is fed, not the per-step samples)."""
    import yaml
    from nonfragile_tracker.bag.replay import replay
    from nonfragile_tracker.workflows.runner import run_composed, scenario_parameters
    K = read_gain_file(CONFIG / 'tracker_gains.yaml')
    gains = tmp_path / 'g.yaml'
    gains.write_text(yaml.safe_dump({'/**/tracker': {'ros__parameters': {
        'K': [float(v) for v in np.asarray(K).ravel()], 'K_shape': [2, 4],
        'predict_latency': 0.035, 'predict_odom_latency': 0.0, 'predict_lag_v': 0.045,
        'predict_lag_w': 0.06}}}))
    scenario_file = CONFIG / 'line_arc_scenario.yaml'
    ov = {'plant': {'ros__parameters': {'duration': 16.0, 'initial_pose': [0.0, 0.0, 0.0]}},
          'reference': {'ros__parameters': {'trajectory_file': str(LAP)}},
          'tracker': {'ros__parameters': {'wait_for_trajectory': True}}}
    params = scenario_parameters(scenario_file, gains, ov)
    assert params['tracker']['ros__parameters']['predict_latency'] == 0.035   # the gain file's
    res = run_composed(params, tmp_path / 'run', record_all=record_all)
    assert all(c == 0 for c in res.exit_codes.values()), res.exit_codes
    rep = replay(res.bag, gains=gains, params=scenario_file)
    assert rep.inputs.get('trajectory') == 1
    assert {e.kind for e in rep.plan.events} == {'odom', 'trajectory'}  # samples not fed
    assert len(rep.commands) == len(rep.recorded) == 801               # odometry at 50 Hz
    assert rep.comparison.equal and rep.max_abs_error <= 1e-9
    # the scenario's own predictor (0.04 s) instead of the gain file's: not the same run
    params_only = replay(res.bag, gains=CONFIG / 'tracker_gains.yaml', params=scenario_file)
    assert params_only.max_abs_error > 1e-3
