"""The tracker node's timing report (issue 30 item 1): the measured odometry period on
/diagnostics, a dt override that disagrees with it and a rate that changes reported with
the numbers (WARN, logged once), deadline misses against the measured period."""
import pytest
import rclpy
from geometry_msgs.msg import AccelStamped, PoseStamped, TwistStamped
from nav_msgs.msg import Odometry
from rclpy.parameter import Parameter

from conftest import CONFIG, unique_domain_id
from nonfragile_tracker.control.simulation.gains import read_gain_file
from nonfragile_tracker.control.simulation.reference import circle
from nonfragile_tracker.nodes.common import fill_pose, fill_reference, ns_to_stamp
from nonfragile_tracker.nodes.tracker import TrackerNode

T0 = 1_000_000_000_000


@pytest.fixture
def make_node():
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=unique_domain_id('tracker_timing'))
    nodes = []

    def make(**params):
        K = read_gain_file(CONFIG / 'tracker_gains.yaml')
        n = TrackerNode(context=ctx, parameter_overrides=[
            Parameter('K', value=[float(v) for v in K.ravel()]), Parameter('monitor', value=False),
            *[Parameter(k, value=v) for k, v in params.items()]])
        n.diag = []
        n.pub_diag.publish = n.diag.append
        n.logged = []
        log = n.log
        n.log = lambda level, msg: (n.logged.append((level, msg)), log(level, msg))
        nodes.append(n)
        return n
    yield make
    for n in nodes:
        n.destroy_node()
    rclpy.try_shutdown(context=ctx)


def step(node, ns):
    """One odometry message (and the reference samples) stamped ``ns``."""
    ref = circle().sample((ns - T0) * 1e-9)
    odom = Odometry()
    odom.header.frame_id = 'odom'
    ns_to_stamp(ns, odom.header.stamp)
    fill_pose(odom.pose.pose, ref.x, ref.y, 1.57)
    odom.twist.twist.linear.x = 0.005
    parts = (PoseStamped(), TwistStamped(), AccelStamped())
    for m in parts:
        m.header.frame_id = 'odom'
        ns_to_stamp(ns, m.header.stamp)
    fill_reference(ref._replace(heading=0.0), *parts)
    node._on_ref_pose(parts[0])
    node._on_ref_twist(parts[1])
    node._on_ref_accel(parts[2])
    node._on_odom(odom)


def status(node):
    node._diagnostics()
    st = node.diag[-1].status[0]
    return st, {kv.key: kv.value for kv in st.values}


def test_a_disagreeing_dt_override_is_reported_with_both_numbers(make_node):
    node = make_node(dt=0.01)
    for k in range(30):
        step(node, T0 + k * 20_000_000)                 # 50 Hz odometry, dt told 10 ms
    st, vals = status(node)
    assert st.level == b'\x01'
    assert 'dt = 0.01 s is set but the odometry period is 0.0200 s (50.0 Hz)' in st.message
    assert vals['odometry period (s)'] == '0.020000'
    assert vals['tracker step (s)'] == '0.01 (dt override)'
    assert vals['deadline misses'] == '0'               # 20 ms is the period, not a miss
    status(node)
    said = [m for lv, m in node.logged if 'odometry period is' in m]
    assert len(said) == 1 and said[0].startswith('dt = 0.01 s')     # logged once


def test_the_default_measures_the_period_and_reports_a_change_once(make_node):
    node = make_node()
    for k in range(20):
        step(node, T0 + k * 10_000_000)                 # 100 Hz
    st, vals = status(node)
    assert st.level == b'\x00' and vals['odometry period (s)'] == '0.010000'
    assert vals['tracker step (s)'] == 'from the odometry stamps (dt 0)'
    t = T0 + 19 * 10_000_000
    for k in range(1, 20):
        step(node, t + k * 20_000_000)                  # 50 Hz from now on
    st, vals = status(node)
    assert st.level == b'\x01' and vals['odometry period (s)'] == '0.020000'
    assert ('odometry period changed from 0.0100 s (100.0 Hz) to 0.0200 s (50.0 Hz)'
            in st.message)
    assert int(vals['deadline misses']) <= 5            # until the median moves (half a window)
    st, _ = status(node)
    assert 'changed' not in st.message and st.level == b'\x00'       # reported once


def test_the_monitor_is_stale_while_the_robot_rests_after_its_trajectory(make_node):
    """Issue 30 item 5, in the node: an estimate that would WARN (a lag of 100 ms against
    the certified 41 ms) gives STALE once the trajectory is finished (at rest)."""
    from types import SimpleNamespace

    from nonfragile_tracker.control.identification.monitor import LatencyEstimate
    node = make_node(monitor=True, certified_residual=[0.0, 0.15], certified_lag=0.041,
                     monitor_period=100.0)
    node.monitor.latest = LatencyEstimate(True, '', t_end=10.0, latency=0.1,
                                          interval=(0.098, 0.102), lag_v=0.1, lag_w=0.1,
                                          r2=0.99, confidence=0.99, valid_fraction=1.0,
                                          channels=('v', 'w'))
    (st,) = node._monitor_diagnostics()
    assert st.level == b'\x01' and 'actuator lag 100 ms above the certified 41 ms' in st.message
    node.inputs.follower = SimpleNamespace(finished=True, refused=None, started=True)
    (st,) = node._monitor_diagnostics()
    assert st.level == b'\x03' and 'at rest (trajectory finished): no excitation' in st.message


def test_the_real_time_plant_stamps_the_time_of_its_motion_when_a_tick_is_late():
    """A late timer tick (a loaded machine): the plant takes the steps it missed, publishes
    each with its own stamp (a burst), and never stamps ahead of its clock - the stamps
    stay the time of the motion, which the tracker integrates over.  After a stall of
    seconds it integrates every step but publishes only the last MAX_BURST."""
    from nonfragile_tracker.interface.msgconv import stamp_ns
    from nonfragile_tracker.nodes.plant import MAX_BURST, PlantNode
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=unique_domain_id('plant_timing'))
    plant = PlantNode(context=ctx, parameter_overrides=[
        Parameter('mode', value='realtime'), Parameter('duration', value=0.0)])
    try:
        plant.destroy_timer(plant.timer)                  # ticks by hand, clock by hand
        clock = {'ns': T0}
        plant.get_clock = lambda: type('C', (), {'now': lambda self: type(
            'T', (), {'nanoseconds': clock['ns']})()})()
        stamps = []
        send = plant._publish_state
        plant._publish_state = lambda ns, publish=True: (
            stamps.append((ns, plant.plant.k)), send(ns, publish))[1]
        plant.cmd, plant.last_cmd_time = (0.2, 0.0), None
        dt = plant.dt_ns
        for late in (0, 0, 0, int(2.5 * dt), 0, -dt // 10, 0):     # tick n at T0 + n dt + late
            n = len({s for s, _ in stamps})
            clock['ns'] = T0 + n * dt + late
            plant._realtime_step()
            assert all(s <= clock['ns'] for s, _ in stamps)        # never ahead of the clock
        ks = [k for _, k in stamps]
        assert ks == list(range(9))         # no step skipped: the late tick took 3, 4 and 5
        # each at its own time: T0 + k dt, from the early tick on the earlier grid
        assert [s for s, _ in stamps] == [T0 + k * dt - (dt // 10 if k >= 7 else 0)
                                          for k in ks]
        assert plant.plant.k == 9
        assert plant.plant.x == pytest.approx(0.2 * 9 * dt * 1e-9, rel=0.3)   # it moved on
        # a stall of 3 s: every step integrated, the last MAX_BURST published
        odoms = []
        plant.pub_odom.publish = lambda msg: odoms.append(stamp_ns(msg.header.stamp))
        x0 = plant.plant.x
        clock['ns'] += 3 * 10 ** 9
        plant._realtime_step()
        late = 3 * 10 ** 9 // dt
        assert plant.plant.k == 9 + late
        assert plant.plant.x - x0 == pytest.approx(0.2 * 3.0, rel=0.05)    # moved all along
        assert 0 < len(odoms) <= MAX_BURST and odoms == sorted(odoms)
        assert odoms[-1] <= clock['ns'] and clock['ns'] - odoms[0] < MAX_BURST * dt
    finally:
        plant.destroy_node()
        rclpy.try_shutdown(context=ctx)
