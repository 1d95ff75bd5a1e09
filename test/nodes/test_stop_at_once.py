"""Nodes that stop at once (issue 30, item 4), in process: the reference's start-up with
an hour's trajectory and the tracker's lockstep callback for it look for a stop signal
between their pieces of work.  (Whole processes under an emulated ``ros2 launch``:
test_signals.py.)"""
from __future__ import annotations

import signal
import time

import numpy as np
import pytest
import rclpy

from conftest import CONFIG, unique_domain_id
from nonfragile_tracker.control.simulation.reference import make_path
from nonfragile_tracker.control.simulation.trajectory import analytic_knots
from nonfragile_tracker.interface.msgconv import multidof_cdr, multidof_from_cdr, multidof_to_trajectory
from nonfragile_tracker.nodes import entry
from nonfragile_tracker.nodes.common import overrides
from nonfragile_tracker.nodes.errors import StartupStopped
from nonfragile_tracker.nodes.reference import ReferenceNode
from nonfragile_tracker.nodes.tracker import SYNC_POINTS, TrackerNode
from nonfragile_tracker.interface.scenario import node_parameters

HOUR = dict(path='figure_eight', radius=1.0, rate=0.2, horizon=3600.0)


@pytest.fixture
def context(request):
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=unique_domain_id(request.node.name))
    yield ctx
    ctx.try_shutdown()


def test_reference_builds_an_hour_and_stops_on_a_signal_noted_meanwhile(context,
                                                                        monkeypatch):
    node = ReferenceNode(context=context, parameter_overrides=overrides(**HOUR))
    try:
        assert node.traj.knots.size == 48_001 and node.traj.t_end == 3600.0
    finally:
        node.destroy_node()
    monkeypatch.setattr(entry, '_received', [signal.SIGINT])      # Ctrl-C came meanwhile
    with pytest.raises(StartupStopped):                            # run() ends with 0
        ReferenceNode(context=context, parameter_overrides=overrides(**HOUR))


def _tracker(context):
    values = node_parameters('tracker', CONFIG / 'latency_scenario.yaml')
    values.update(node_parameters('tracker', CONFIG / 'tracker_gains.yaml'))
    return TrackerNode(context=context, parameter_overrides=overrides(**values))


def test_tracker_takes_a_long_trajectory_in_its_worker_and_stops_waiting_for_it(
        context, monkeypatch):
    """Lockstep: more than SYNC_POINTS points are built and re-timed in the worker thread
    (the very trajectory built in the callback: the same floats), and a stop signal ends
    the callback's wait without adopting it."""
    t_ns, s = analytic_knots(make_path('figure_eight', radius=1.0, rate=0.2), 600.0)
    assert t_ns.size > SYNC_POINTS
    raw = multidof_cdr(t_ns, s.x, s.y, s.heading, s.vx, s.vy, s.ax, s.ay, 0, 'odom')
    tracker = _tracker(context)
    try:
        tracker._on_multidof(raw)
        got = tracker.inputs.follower.trajectory
        want, _ = tracker.inputs.retime(multidof_to_trajectory(
            multidof_from_cdr(raw), frame='odom', source='t')[0])
        assert np.array_equal(got._pp.c, want._pp.c) and np.array_equal(got.knots, want.knots)
    finally:
        tracker.destroy_node()
    tracker = _tracker(context)
    try:
        # the work takes longer than the first look (50 ms): stop then
        slow = tracker._build_and_retime

        def slower(*args):
            time.sleep(2.0)
            return slow(*args)
        monkeypatch.setattr(tracker, '_build_and_retime', slower)
        monkeypatch.setattr(entry, '_received', [signal.SIGINT])
        t0 = time.monotonic()
        tracker._on_multidof(raw)
        assert time.monotonic() - t0 < 1.5                 # not the 2 s of the work
        assert tracker.inputs.follower is None             # nothing adopted
    finally:
        monkeypatch.setattr(entry, '_received', [])
        tracker.destroy_node()
