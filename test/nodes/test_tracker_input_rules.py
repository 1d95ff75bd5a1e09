"""The tracker node and the bag replay decide alike: the same message sequence, fed to the
node's callbacks (rclpy messages) and to the replay (the same messages as a bag holds them,
rosbags-deserialized), gives the same commands and the same refusals, with a configured
odometry frame (``world``).  No spinning: the callbacks are called directly."""
from __future__ import annotations

import math

import pytest
import rclpy
from geometry_msgs.msg import AccelStamped, PoseStamped, TwistStamped
from nav_msgs.msg import Odometry
from rclpy.serialization import serialize_message

from nonfragile_tracker.bag.replay import TRACKER_DEFAULTS, ReplayEvent, plan_replay, replay_rules
from nonfragile_tracker.control.identification.tuning import Tuned
from nonfragile_tracker.bag.typestore import jazzy_typestore
from nonfragile_tracker.control.simulation.gains import read_gain_file
from nonfragile_tracker.control.simulation.reference import circle
from nonfragile_tracker.interface.msgconv import fill_pose, fill_reference, ns_to_stamp, tracker_config
from nonfragile_tracker.nodes.common import overrides
from nonfragile_tracker.nodes.tracker import TrackerNode

from conftest import CONFIG, unique_domain_id

pytestmark = pytest.mark.ros

MS = 1_000_000
T0 = 1_800_000_000 * 10 ** 9
FRAME = 'world'
TYPES = {'odom': (Odometry, '/odom', 'nav_msgs/msg/Odometry'),
         'ref_pose': (PoseStamped, '/reference/pose', 'geometry_msgs/msg/PoseStamped'),
         'ref_twist': (TwistStamped, '/reference/twist', 'geometry_msgs/msg/TwistStamped'),
         'ref_accel': (AccelStamped, '/reference/accel', 'geometry_msgs/msg/AccelStamped')}
REF_KINDS = ('ref_pose', 'ref_twist', 'ref_accel')


def step_messages(k: int, odom_ns: int, ref_ns: int, fault: str = ''):
    """The reference parts and odometry of step ``k``, with an optional fault."""
    path = circle()
    r = path.sample(k * 0.01)
    parts = [PoseStamped(), TwistStamped(), AccelStamped()]
    for m in parts:
        m.header.frame_id = 'map' if fault == 'ref frame' else FRAME
        ns_to_stamp(ref_ns, m.header.stamp)
    fill_reference(r, *parts)
    if fault == 'ref nan':
        parts[1].twist.linear.x = math.nan
    odom = Odometry()
    odom.header.frame_id = 'odom' if fault == 'odom frame' else FRAME
    ns_to_stamp(odom_ns, odom.header.stamp)
    fill_pose(odom.pose.pose, r.x + 0.02 * math.sin(k), r.y - 0.01, r.heading + 0.05)
    if fault == 'pose nan':
        odom.pose.pose.position.x = math.nan
    odom.twist.twist.linear.x = 0.3
    return [(kind, m) for kind, m in zip(REF_KINDS, parts)], ('odom', odom)


FAULTS = {3: 'odom frame', 8: 'pose nan', 10: 'ref nan', 12: 'ref frame'}


def realtime_sequence(n: int = 40):
    """References 5 ms before each odometry; faults, a stamp going backwards, a repeat,
    and a 1.5 s jump (beyond max_stamp_jump)."""
    seq = []
    shift = 0
    for k in range(n):
        if k == 20:
            shift = 1500 * MS
        t = T0 + k * 10 * MS + shift
        refs, odom = step_messages(k, t, t - 5 * MS, FAULTS.get(k, ''))
        seq += refs + [odom]
        if k == 6:
            seq.append(odom)                                         # a repeat
        if k == 15:
            seq.append(step_messages(k, T0 + 10 * 10 * MS, 0)[1])   # going backwards
    return seq


def lockstep_sequence(n: int = 40):
    """One stamp per step; every third step the odometry comes before its references
    (the node keeps the references by stamp, the replay feeds a lockstep bag by stamp)."""
    seq = []
    for k in range(n):
        shift = 1500 * MS if k >= 20 else 0
        t = T0 + k * 10 * MS + shift
        refs, odom = step_messages(k, t, t, FAULTS.get(k, ''))
        seq += [odom] + refs if k % 3 == 0 else refs + [odom]
    return seq


@pytest.fixture(scope='module')
def context():
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=unique_domain_id('input_rules'))
    yield ctx
    rclpy.try_shutdown(context=ctx)


def values() -> dict:
    K = read_gain_file(CONFIG / 'tracker_gains.yaml')
    return {**TRACKER_DEFAULTS, 'K': [float(v) for v in K.ravel()], 'K_shape': [2, 4],
            'odom_frame': FRAME}


def through_node(context, mode: str, seq, **params):
    node = TrackerNode(context=context, parameter_overrides=overrides(
        K=values()['K'], mode=mode, odom_frame=FRAME, **params))
    sent = []
    node.pub_cmd.publish = lambda msg: sent.append((msg.linear.x, msg.angular.z))
    try:
        on = {'odom': node._on_odom, 'ref_pose': node._on_ref_pose,
              'ref_twist': node._on_ref_twist, 'ref_accel': node._on_ref_accel}
        for kind, msg in seq:
            on[kind](msg)
        assert isinstance(node.tracker, Tuned) == (node.config.rules.tune is not None)
        return sent, dict(node.inputs.ignored), node.inputs.rejected, node.inputs.jumps
    finally:
        node.destroy_node()


def through_replay(seq, **params):
    ts = jazzy_typestore()
    events = []
    for i, (kind, msg) in enumerate(seq):
        _, topic, msgtype = TYPES[kind]
        raw = serialize_message(msg)
        events.append(ReplayEvent(kind, T0 + i * MS, topic, msgtype, raw,
                                  ts.deserialize_cdr(raw, msgtype)))
    v = {**values(), **params}
    plan = plan_replay(events, tracker_config(v), use_recorded=False, values=v)
    return plan, [(m.linear.x, m.angular.z) for _, m in plan.commands]


@pytest.mark.parametrize('mode, sequence', [('realtime', realtime_sequence),
                                            ('lockstep', lockstep_sequence)])
def test_node_and_replay_decide_alike(context, mode, sequence):
    seq = sequence()
    # both with the node's defaults: the predictor tuned online (monitor_tune, monitor on)
    assert replay_rules(values(), mode).tune is not None
    sent, ignored, rejected, jumps = through_node(context, mode, seq)
    plan, replayed = through_replay(seq)
    assert plan.mode == mode
    assert replayed == sent                                   # the same commands, exactly
    assert plan.ignored == ignored
    assert sum(ignored.values()) == rejected
    assert "odom in frame 'odom' (expected 'world')" in ignored
    assert ignored["reference in frame 'map' (expected 'world')"] == 3      # each part
    assert any(r.startswith('odom: non-finite pose') for r in ignored)
    assert any(r.startswith('reference twist/accel not finite') for r in ignored)
    # 40 steps: one lost to each of the four faults (the refused reference frame leaves the
    # pose part of that stamp missing in lockstep; in real time the latest parts stand in)
    expected = 40 - 4 if mode == 'lockstep' else 40 - 3
    assert len(sent) == expected and jumps == 1
    if mode == 'realtime':
        assert ignored['odom stamp going backwards'] == 1 and rejected == 7
    else:
        # lockstep: the stamp with the non-finite reference is tried again at each sample
        # that arrives until the next odometry replaces it (3 of the next step): 4 refusals
        assert rejected == 9 and sum(n for r, n in ignored.items()
                                     if r.startswith('reference twist')) == 4


def test_without_the_monitor_there_is_no_tuning_in_the_node_nor_the_replay(context, capfd):
    """``monitor: false`` means no online tuning (its estimates are the monitor's): the node
    starts (saying so when ``monitor_tune`` is set) and the replay of the same parameters
    does not tune either; the two still decide alike."""
    params = dict(monitor=False, monitor_tune=True)
    node = TrackerNode(context=context, parameter_overrides=overrides(
        K=values()['K'], mode='lockstep', odom_frame=FRAME, **params))
    try:
        assert node.lifecycle_state() == 'active'
        assert not isinstance(node.tracker, Tuned) and node.monitor is None
        assert node.config.rules.tune is None
    finally:
        node.destroy_node()
    assert 'the predictor is not tuned online' in capfd.readouterr().err
    assert replay_rules(params, 'lockstep').tune is None
    assert replay_rules(dict(params, monitor=True), 'lockstep').tune is not None
    seq = lockstep_sequence()
    sent = through_node(context, 'lockstep', seq, **params)[0]
    assert through_replay(seq, **params)[1] == sent and len(sent) == 36
