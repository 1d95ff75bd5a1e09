"""A real-time run of our nodes, recorded: report, compare and replay it (in process, over DDS)."""
from __future__ import annotations

import os
import subprocess
import sys
import time

import numpy as np
import pytest
from test_realtime_faults import Probe, start, stop

from conftest import ROOT, unique_domain_id
from nonfragile_tracker.bag.compare import compare_bags
from nonfragile_tracker.bag.reader import read_messages
from nonfragile_tracker.bag.replay import replay
from nonfragile_tracker.bag.report import bag_report

pytestmark = [pytest.mark.ros, pytest.mark.slow]

TOPICS = "['odom','reference/pose','reference/twist','reference/accel','cmd_vel','tracker/tuning']"
INPUTS = ('odom', 'reference/pose', 'reference/twist', 'reference/accel')


@pytest.fixture(scope='module')
def realtime_bag(tmp_path_factory):
    """~5 s of plant, reference and tracker in real time (separate processes), recorded.

    The recorder, plant and reference run first, so the recorder holds every input the
    tracker gets; the tracker's input timeout is long, so it publishes no stop while the
    run is wound down (plant and reference first, then the tracker, then the recorder).
    """
    tmp = tmp_path_factory.mktemp('rt')
    env = dict(os.environ, ROS_DOMAIN_ID=str(unique_domain_id('bag_rt')),
               ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
    env['PYTHONPATH'] = str(ROOT) + os.pathsep + env.get('PYTHONPATH', '')
    probe = Probe(int(env['ROS_DOMAIN_ID']))
    bag = tmp / 'bag'
    procs = {}
    rec_log = tmp / 'recorder.log'
    rec_out = rec_log.open('w')
    try:
        procs['recorder'] = subprocess.Popen(
            [sys.executable, '-m', 'nonfragile_tracker.nodes.recorder', '--ros-args', '-p',
             f'output:={bag}', '-p', f'topics:={TOPICS}'],
            env=dict(env, RCUTILS_LOGGING_BUFFERED_STREAM='0'), stdout=rec_out,
            stderr=subprocess.STDOUT, text=True)
        procs['plant'] = start('plant', env, '-p', 'duration:=0.0')
        procs['reference'] = start('reference', env)
        assert probe.wait_for(lambda: len(probe.odoms) > 50, timeout=20)
        # the tracker starts once the recorder has every input: a graph that lists the
        # recorder's readers is not enough (under load a reader matched its writer seconds
        # later, and the bag lacked the references the tracker's first commands came from)
        assert probe.wait_for(lambda: all(f'first message on /{t}' in rec_log.read_text()
                                          for t in INPUTS), timeout=30), \
            rec_log.read_text()
        procs['tracker'] = start('tracker', env, '-p', 'input_timeout:=30.0')
        assert probe.wait_for(lambda: sum(1 for c in probe.cmds if c[1] != 0.0) > 250,
                              timeout=30), 'no commands from the tracker'
        probe.spin(2.0)          # the recorder may match the tracker's writer late under load
        stop(procs.pop('plant'))
        stop(procs.pop('reference'))
        probe.spin(0.3)
        stop(procs.pop('tracker'))
        probe.spin(0.3)
    finally:
        logs = {k: stop(p) for k, p in procs.items()}
        probe.close()
        rec_out.close()
    assert (bag / 'metadata.yaml').exists(), (logs, rec_log.read_text())
    return bag


def _messages(bag, topic):
    return list(read_messages(bag, topic))


def test_report_of_a_realtime_run_matches_the_messages(realtime_bag, tmp_path):
    rep = bag_report(realtime_bag, tmp_path / 'report')
    assert rep.mode == 'realtime' and rep.metrics is not None
    odom = _messages(realtime_bag, '/odom')
    cmds = _messages(realtime_bag, '/cmd_vel')
    # a reference sample is complete when pose, twist and accel of its stamp are all
    # recorded (the recording may end between them)
    parts = [{m.header.stamp.sec * 10 ** 9 + m.header.stamp.nanosec: m
              for _, m in _messages(realtime_bag, f'/reference/{k}')}
             for k in ('pose', 'twist', 'accel')]
    refs = [(None, parts[0][s]) for s in sorted(set(parts[0]) & set(parts[1]) & set(parts[2]))]
    stamps = np.array(sorted({m.header.stamp.sec * 10 ** 9 + m.header.stamp.nanosec
                              for _, m in odom}))
    tm = rep.timing
    assert tm.odom_count == stamps.size == rep.pose_samples
    assert tm.odom_rate == pytest.approx((stamps.size - 1) / ((stamps[-1] - stamps[0]) * 1e-9),
                                         rel=1e-12)
    assert 60 < tm.odom_rate < 110                     # 100 Hz plant under load
    assert tm.odom_jitter == pytest.approx(np.std(np.diff(stamps) * 1e-9), rel=1e-9)
    crecv = [t for t, _ in cmds]
    assert tm.command_count == len(cmds)
    assert tm.command_rate == pytest.approx((len(crecv) - 1) / ((crecv[-1] - crecv[0]) * 1e-9))
    # latency: each command after the last odometry received before it (loop, not numpy)
    orecv = sorted(t for t, _ in odom)
    lat = []
    for t in crecv:
        before = [r for r in orecv if r <= t]
        if before:
            lat.append((t - before[-1]) * 1e-9)
    assert tm.latency_median == pytest.approx(float(np.median(lat)), abs=1e-12)
    assert 0 < tm.latency_median < 0.05
    assert tm.late_commands == sum(1 for x in lat if x > tm.odom_step_median)
    # missing: odometry intervals after the first command without a command
    first = next(i for i, r in enumerate(orecv) if r > crecv[0]) - 1
    missing = 0
    for i in range(first, len(orecv)):
        end = orecv[i + 1] if i + 1 < len(orecv) else float('inf')
        missing += not any(orecv[i] <= t < end for t in crecv)
    assert tm.missing_commands == missing
    # tracking: reference interpolated at each pose stamp inside the reference's span
    rt = np.array([m.header.stamp.sec * 10 ** 9 + m.header.stamp.nanosec for _, m in refs])
    inside = [(s, m) for _, m in odom for s in [m.header.stamp.sec * 10 ** 9
                                                  + m.header.stamp.nanosec]
              if rt.min() <= s <= rt.max()]
    assert rep.matched == len({s for s, _ in inside})
    s_last, m_last = max(inside, key=lambda p: p[0])
    # (relative ns: absolute ns as doubles would lose ~0.1 us)
    rx = np.interp(s_last - rt[0], rt - rt[0], [m.pose.position.x for _, m in refs])
    ry = np.interp(s_last - rt[0], rt - rt[0], [m.pose.position.y for _, m in refs])
    assert rep.metrics.final_error == pytest.approx(
        np.hypot(m_last.pose.pose.position.x - rx, m_last.pose.pose.position.y - ry), abs=1e-12)
    assert rep.metrics.peak_abs_w == pytest.approx(max(abs(m.angular.z) for _, m in cmds))
    assert sorted(rep.plots) == ['commands.png', 'errors.png', 'xi.png', 'xy.png']


def test_realtime_bag_equals_itself_and_aligns_by_time(realtime_bag):
    cmp = compare_bags(realtime_bag, realtime_bag)
    assert cmp.equal and cmp.summary['/odom'].align == 'stamp'
    cmp = compare_bags(realtime_bag, realtime_bag, align='time', time_tolerance=0.0)
    assert cmp.equal and cmp.summary['/cmd_vel'].paired == cmp.messages['/cmd_vel']


def test_replay_in_process_reproduces_recorded_commands(realtime_bag):
    res = replay(realtime_bag)
    assert res.mode == 'realtime'
    assert res.comparison.equal, res.comparison.differences[:5]
    # (the recorder may match the tracker's writer after its first commands: > 100, not all)
    assert len(res.commands) == len(res.recorded) > 100
    assert res.max_abs_error <= 1e-9


def test_replay_over_dds_reproduces_recorded_commands(realtime_bag, tmp_path):
    from nonfragile_tracker.workflows.dds_replay import replay_over_dds
    env = dict(os.environ, ROS_DOMAIN_ID=str(unique_domain_id('bag_replay_dds')))
    t0 = time.monotonic()
    res = replay_over_dds(realtime_bag, env=env)
    assert res.comparison.equal, res.comparison.differences[:5]
    assert len(res.commands) == len(res.recorded) > 100
    assert res.max_abs_error <= 1e-9
    assert time.monotonic() - t0 < 60
