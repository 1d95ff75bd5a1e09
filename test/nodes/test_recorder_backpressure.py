"""A recorded lockstep run loses nothing: the plant says how many odometry messages it
sent (the recorder's drain does not wait out drain_timeout with decimated odometry), and
it stays within lockstep_lead steps of a recorder that falls behind (no queue overflow)."""
import threading
import time

import rclpy
from rclpy.executors import SingleThreadedExecutor

from nonfragile_tracker.interface import topics
from nonfragile_tracker.bag.reader import read_bag
from nonfragile_tracker.nodes.common import overrides
from nonfragile_tracker.nodes.plant import PlantNode
from nonfragile_tracker.nodes.recorder import Recorder
from nonfragile_tracker.nodes.reference import ReferenceNode
from nonfragile_tracker.nodes.tracker import TrackerNode
from nonfragile_tracker.workflows.runner import lockstep_parameters, scenario_parameters, with_horizon

from conftest import CONFIG, unique_domain_id

RECORDED = ['/clock', 'odom', 'pose', 'reference/pose', 'reference/twist', 'reference/accel',
            'cmd_vel', 'run_done']


class SlowRecorder(Recorder):
    """A recorder on a loaded machine: every message costs ``delay`` s of its thread."""

    delay = 0.0

    def _make_callback(self, name):
        inner = super()._make_callback(name)

        def slow(raw):
            time.sleep(self.delay)
            inner(raw)
        return slow


def run(tmp_path, name, *, duration, plant=None, tracker=None, delay=0.0, lead=None,
        drain_timeout=30.0):
    """Plant, tracker and reference on one executor thread, the recorder on another."""
    ov = {'plant': {'ros__parameters': dict(duration=duration, **(plant or {}))},
          'tracker': {'ros__parameters': tracker or {}}}
    params = with_horizon(scenario_parameters(CONFIG / 'paper_scenario.yaml',
                                              CONFIG / 'tracker_gains.yaml', ov))
    hand = lockstep_parameters(True)
    # the three nodes share one executor thread: on a loaded machine a command can take
    # longer than lockstep_retry (0.25 s wall), and the republished step would be in the bag
    # twice; these tests judge the back-pressure, the retry has tests of its own
    hand['plant']['lockstep_retry'] = 5.0
    if lead is not None:
        hand['plant']['lockstep_lead'] = lead

    def node_params(node):
        return overrides(**params[node]['ros__parameters'], **hand[node])

    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=unique_domain_id('backpressure' + name))
    SlowRecorder.delay = delay
    rec = SlowRecorder(context=ctx, parameter_overrides=overrides(
        output=str(tmp_path / name), use_sim_time=True, topics=RECORDED,
        drain_timeout=drain_timeout, **hand['recorder']))
    nodes = [TrackerNode(context=ctx, parameter_overrides=node_params('tracker')),
             ReferenceNode(context=ctx, parameter_overrides=node_params('reference'))]
    plant = PlantNode(context=ctx, parameter_overrides=node_params('plant'))
    nodes.append(plant)
    loop_ex, rec_ex = SingleThreadedExecutor(context=ctx), SingleThreadedExecutor(context=ctx)
    for n in nodes:
        loop_ex.add_node(n)
    rec_ex.add_node(rec)
    ended = {}

    def spin(ex, key):
        # both run until the recorder is done (the reference answers the last /clock
        # messages after the plant has finished); note when the plant finished
        deadline = time.monotonic() + 120
        while ctx.ok() and not rec.finished and time.monotonic() < deadline:
            ex.spin_once(timeout_sec=0.01)
            if plant.finished and 'plant' not in ended:
                ended['plant'] = time.monotonic()
        ended[key] = time.monotonic()

    threads = [threading.Thread(target=spin, args=(loop_ex, 'loop')),
               threading.Thread(target=spin, args=(rec_ex, 'recorder'))]
    try:
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        assert plant.finished and plant.exit_code == 0 and rec.finished
        return read_bag(tmp_path / name, strict=False), plant, ended
    finally:
        for n in [*nodes, rec]:
            n.destroy_node()
        rclpy.try_shutdown(context=ctx)


def test_decimated_odometry_drains_at_once(tmp_path):
    """odom every 5th step, 2 steps late: the recorder knows the count and closes at once."""
    bag, plant, ended = run(tmp_path, 'decimated', duration=2.0,
                            plant={'odom_rate': 20.0, 'odom_latency': 0.02},
                            tracker={'dt': 0.05})
    steps = 200
    # measurements at steps 0, 5, ..., 195 (the one of step 200 would appear at step 202)
    assert plant.odom_sent == 40
    assert bag.counts['/odom'] == 40 and bag.counts['/cmd_vel'] == 40
    for name in ('/clock', '/pose', '/reference/pose', '/reference/twist', '/reference/accel'):
        assert bag.counts[name] == steps + 1, name
    assert ended['recorder'] - ended['plant'] < 5.0       # drain_timeout is 30 s


def test_a_slow_recorder_holds_the_plant_back_and_loses_nothing(tmp_path):
    """7 messages a step at 1 ms each: the recorder takes 7 ms a step, the loop about 1 ms;
    300 steps would put the plant 250 steps (beyond the queues' depth 100) ahead."""
    steps = 300
    bag, plant, _ = run(tmp_path, 'slow', duration=steps * 0.01, delay=0.001)
    assert plant.holds > 0                                # the recorder really fell behind
    for name in ('/clock', '/odom', '/pose', '/reference/pose', '/reference/twist',
                 '/reference/accel', '/cmd_vel'):
        assert bag.counts[name] == steps + 1, name
    assert bag.counts['/run_done'] == 1
    assert len(bag.run.pose) == steps + 1 and len(bag.run.reference.x) == steps + 1


def test_without_back_pressure_the_same_recorder_loses_messages(tmp_path):
    """The same run with lockstep_lead 0: the recorder's queues overflow (what the
    back-pressure prevents)."""
    steps = 300
    bag, plant, _ = run(tmp_path, 'unpaced', duration=steps * 0.01, delay=0.001, lead=0,
                        drain_timeout=0.5)
    assert plant.holds == 0
    assert bag.counts['/clock'] < steps + 1 - 50
    assert topics.RECORDER_PROGRESS not in bag.counts
