"""The recorder as a separate process: SIGINT, SIGKILL + repair, and run_done handling.

Each test uses its own ROS_DOMAIN_ID (from the pid) on localhost; publishers wait until
the recorder's subscriptions are matched (never a fixed sleep).
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import rclpy
from geometry_msgs.msg import AccelStamped, PoseStamped, Twist, TwistStamped
from nav_msgs.msg import Odometry
from rclpy.context import Context
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import serialize_message
from std_msgs.msg import UInt64

from conftest import ROOT, domain_ids
from nonfragile_tracker.interface import topics
from nonfragile_tracker.bag.reader import mcap_is_complete, read_bag, read_messages
from nonfragile_tracker.bag.repair import repair_bag, scan_mcap

PY = str(ROOT / '.venv' / 'bin' / 'python') if (ROOT / '.venv').exists() else sys.executable
DATA_QOS = QoSProfile(depth=topics.DEPTH, reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.VOLATILE)
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
CLASSES = {topics.ODOM: Odometry, topics.POSE: PoseStamped, topics.REF_POSE: PoseStamped,
           topics.REF_TWIST: TwistStamped, topics.REF_ACCEL: AccelStamped, topics.CMD_VEL: Twist}
DT_NS = 10_000_000


def _domain(index: int) -> int:
    return domain_ids('recorder-node', 6)[index]


class Session:
    """The recorder process and a publishing node in this process, on one domain."""

    def __init__(self, tmp_path: Path, index: int, params: dict):
        self.domain = _domain(index)
        self.bag = tmp_path / 'bag'
        env = dict(os.environ, ROS_DOMAIN_ID=str(self.domain),
                   ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
                   PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get('PYTHONPATH', ''))
        args = ['-p', f'output:={self.bag}']
        for k, v in params.items():
            args += ['-p', f'{k}:={v}']
        self.log = open(tmp_path / 'recorder.log', 'w+')
        self.proc = subprocess.Popen([PY, '-m', 'nonfragile_tracker.nodes.recorder',
                                      '--ros-args', *args], env=env, cwd=tmp_path,
                                     stdout=self.log, stderr=subprocess.STDOUT)
        self.ctx = Context()
        rclpy.init(context=self.ctx, domain_id=self.domain)
        self.node = Node('test_publisher', context=self.ctx)
        self.pubs = {}

    def publishers(self, names, qos=DATA_QOS, cls=None):
        for n in names:
            self.pubs[n] = self.node.create_publisher(cls or CLASSES[n], n, qos)
        deadline = time.monotonic() + 30.0
        while not all(self.pubs[n].get_subscription_count() >= 1 for n in names):
            assert self.proc.poll() is None, f'recorder died: {self.output()}'
            assert time.monotonic() < deadline, 'recorder subscriptions not matched in 30 s'
            time.sleep(0.02)

    def publish(self, name: str, k: int) -> bytes:
        msg = CLASSES[name]()
        if hasattr(msg, 'header'):
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(k * DT_NS, 10 ** 9)
            msg.header.frame_id = topics.ODOM_FRAME
        if name == topics.ODOM:
            msg.pose.pose.position.x = 0.1 * k
            msg.twist.twist.linear.x = 0.5 + k
        elif name == topics.CMD_VEL:
            msg.linear.x, msg.angular.z = 0.01 * k, -0.02 * k
        elif hasattr(msg, 'pose'):
            msg.pose.position.y = 1.0 + k
        raw = serialize_message(msg)
        self.pubs[name].publish(raw)     # the exact bytes on the wire (CDR padding included)
        return raw

    def acked(self, timeout: float = 10.0) -> None:
        for pub in self.pubs.values():
            assert pub.wait_for_all_acked(Duration(seconds=timeout))

    def wait(self, timeout: float) -> int:
        try:
            return self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
            pytest.fail(f'recorder did not exit in {timeout} s: {self.output()}')

    def output(self) -> str:
        self.log.flush()
        self.log.seek(0)
        return self.log.read()

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.ctx)
        self.log.close()


@pytest.fixture
def session(tmp_path, monkeypatch):
    monkeypatch.setenv('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')   # for this process too
    sessions = []

    def start(index: int, **params) -> Session:
        s = Session(tmp_path, index, params)
        sessions.append(s)
        return s
    yield start
    for s in sessions:
        s.close()


@pytest.mark.parametrize('sig', [signal.SIGINT, signal.SIGTERM], ids=['SIGINT', 'SIGTERM'])
def test_signal_closes_a_complete_bag(session, sig):
    s = session(0 if sig == signal.SIGINT else 4)
    names = [topics.ODOM, topics.CMD_VEL, topics.REF_POSE]
    s.publishers(names)
    sent = {n: [s.publish(n, k) for k in range(40)] for n in names}
    s.acked()
    deadline = time.monotonic() + 10
    while sum(len(v) for v in sent.values()) > _recorded(s.bag) and time.monotonic() < deadline:
        time.sleep(0.05)                 # the recorder flushes every flush_period (1 s)
    s.proc.send_signal(sig)
    assert s.wait(15) == 0, s.output()
    assert (s.bag / 'metadata.yaml').exists() and mcap_is_complete(s.bag / 'bag.mcap')
    data = read_bag(s.bag, strict=False)
    assert data.counts == {'/odom': 40, '/cmd_vel': 40, '/reference/pose': 40}
    for n in names:
        assert [bytes(r) for r in _raw_topic(s.bag, '/' + n)] == sent[n]
    assert [m.pose.pose.position.x for _, m in read_messages(s.bag, 'odom')] == \
        pytest.approx([0.1 * k for k in range(40)], abs=0)
    # offered QoS of the real publisher (as ros2 bag record stores it)
    qos = data.offered_qos['/odom'][0]
    assert qos.reliability.name == 'RELIABLE' and qos.durability.name == 'VOLATILE'
    # independent reader
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    with open(s.bag / 'bag.mcap', 'rb') as f:
        got = [(c.topic, d) for _, c, _, d in
               make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages()]
    assert [d.angular.z for t, d in got if t == '/cmd_vel'] == [-0.02 * k for k in range(40)]


def _recorded(bag: Path) -> int:
    files = list(bag.glob('*.mcap'))
    return len(scan_mcap(files[0]).messages) if files else 0


def _raw_topic(bag: Path, topic: str):
    from rosbags.rosbag2 import Reader
    with Reader(bag) as reader:
        conns = [c for c in reader.connections if c.topic == topic]
        return [raw for _, _, raw in reader.messages(connections=conns)]


def test_sigkill_then_repair_recovers_flushed_messages(session, tmp_path):
    s = session(1, flush_period=0.2)
    names = [topics.ODOM, topics.CMD_VEL]
    s.publishers(names)
    sent = {n: [s.publish(n, k) for k in range(30)] for n in names}
    s.acked()
    deadline = time.monotonic() + 10
    while _recorded(s.bag) < 60:        # wait for the timer flush to put them on disk
        assert time.monotonic() < deadline, 'recorder did not flush within 10 s'
        time.sleep(0.05)
    for n in names:                     # more messages, then a kill mid-run
        sent[n] += [s.publish(n, k) for k in range(30, 60)]
    s.proc.send_signal(signal.SIGKILL)
    assert s.wait(10) == -signal.SIGKILL
    assert not (s.bag / 'metadata.yaml').exists()
    res = repair_bag(s.bag)
    assert res.output == tmp_path / 'bag_repaired'
    assert res.total >= 60 and not res.complete_source
    for n in names:
        got = [bytes(r) for r in _raw_topic(res.output, '/' + n)]
        assert len(got) >= 30
        assert got == sent[n][:len(got)]         # byte-identical, in order, nothing invented


def test_run_done_drains_and_exits(session):
    s = session(2, drain_timeout=20.0)
    names = list(CLASSES)
    s.publishers(names)
    s.publishers([topics.RUN_DONE], qos=LATCHED, cls=UInt64)
    S = 24
    for k in range(S + 1):
        for n in names:
            s.publish(n, k)
        if k == 3:
            s.publish(topics.ODOM, 3)           # a republished step is not a new sample
    t0 = time.monotonic()
    s.pubs[topics.RUN_DONE].publish(UInt64(data=S))
    assert s.wait(15) == 0, s.output()
    assert time.monotonic() - t0 < 10.0          # finished by itself, not by drain_timeout
    assert 'all samples received' in s.output()
    data = read_bag(s.bag)
    for n in names:
        assert data.count(n) == S + 1 + (n == topics.ODOM), n
    assert data.count(topics.RUN_DONE) == 1 and data.duplicates == {'/odom': 1}
    assert len(data.run.pose) == S + 1 and len(data.run.commands) == S + 1


def test_run_done_shortfall_times_out_with_a_warning(session):
    s = session(3, drain_timeout=1.0, topics='[odom, cmd_vel, run_done]')
    s.publishers([topics.ODOM, topics.CMD_VEL])
    s.publishers([topics.RUN_DONE], qos=LATCHED, cls=UInt64)
    S = 9
    for k in range(S + 1):
        s.publish(topics.ODOM, k)
        if k < S:
            s.publish(topics.CMD_VEL, k)
    s.pubs[topics.RUN_DONE].publish(UInt64(data=S))
    assert s.wait(15) == 0, s.output()
    out = s.output()
    assert 'drain timeout' in out and '/cmd_vel short by 1' in out, out
    data = read_bag(s.bag, strict=False)
    assert data.counts == {'/odom': S + 1, '/cmd_vel': S, '/run_done': 1}


def test_recorder_in_process(tmp_path, monkeypatch):
    """Recorder(**node_kwargs) in a shared executor: done completes after run_done."""
    from rclpy.executors import SingleThreadedExecutor

    from nonfragile_tracker.nodes.common import overrides
    from nonfragile_tracker.nodes.recorder import Recorder
    monkeypatch.setenv('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    ctx = Context()
    rclpy.init(context=ctx, domain_id=_domain(5))
    rec = node = None
    try:
        rec = Recorder(context=ctx, parameter_overrides=overrides(
            output=str(tmp_path / 'bag'), topics=['cmd_vel', 'run_done'], drain_timeout=5.0))
        node = Node('feeder', context=ctx)
        pub = node.create_publisher(Twist, topics.CMD_VEL, DATA_QOS)
        done = node.create_publisher(UInt64, topics.RUN_DONE, LATCHED)
        ex = SingleThreadedExecutor(context=ctx)
        ex.add_node(rec)
        ex.add_node(node)
        deadline = time.monotonic() + 20
        while pub.get_subscription_count() < 1:
            assert time.monotonic() < deadline
            ex.spin_once(timeout_sec=0.02)
        for k in range(3):
            pub.publish(Twist())
        done.publish(UInt64(data=2))
        while not rec.done.done():
            assert time.monotonic() < deadline, 'recorder did not finish'
            ex.spin_once(timeout_sec=0.05)
        assert rec.done.result() == {'cmd_vel': 3, 'run_done': 1} and rec.finished
        from rclpy.parameter import Parameter
        with pytest.raises(Exception, match='exists already'):
            Recorder(context=ctx, node_name='again',
                     parameter_overrides=[Parameter('output', value=str(tmp_path / 'bag'))])
        assert read_bag(tmp_path / 'bag', strict=False).counts == {'/cmd_vel': 3,
                                                                   '/run_done': 1}
    finally:
        for n in (rec, node):
            if n is not None:
                n.destroy_node()
        rclpy.try_shutdown(context=ctx)
