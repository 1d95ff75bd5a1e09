"""Replay a bag over DDS into a real tracker node and compare its commands.

:func:`replay_over_dds` starts the tracker node in its own process, publishes the recorded
odometry and reference messages (their recorded CDR bytes, unchanged) in bag order, waiting
for each command the tracker's input rules
(:class:`~nonfragile_tracker.interface.tracker_inputs.TrackerInputs`) predict before the next, and
collects and compares the node's ``cmd_vel``.

See doc/bags.md, section "``bag replay``" (over DDS).
"""
from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path
from typing import Any, Callable

import rclpy
from geometry_msgs.msg import AccelStamped, PoseStamped, Twist, TwistStamped
from nav_msgs.msg import Odometry

from ..interface import topics
from ..bag.replay import (REF_INDEX, ReplayResult, finish_replay, load_tracker_parameters,
                          plan_replay, read_replay_events, recorded_tuning, replay_rules)
from ..bag.errors import BagError
from ..bag.typestore import jazzy_typestore
from ..errors import RunError
from ..nodes.common import DATA_QOS
from .runner import NodeProcess, reserved_domain, write_parameter_file
from ..interface.tracker_inputs import TrackerInputs

__all__ = ['replay_over_dds']

_TYPES = {'odom': (Odometry, topics.ODOM), 'ref_pose': (PoseStamped, topics.REF_POSE),
          'ref_twist': (TwistStamped, topics.REF_TWIST),
          'ref_accel': (AccelStamped, topics.REF_ACCEL)}
#: input_timeout given to the node: replay pacing must not trigger its watchdog.
NO_WATCHDOG = 1e5
#: Seconds to let discovery settle after the node is matched, and after the first inputs.
SETTLE = 1.0


def replay_over_dds(bag: str | os.PathLike[str], *, gains: str | os.PathLike[str] | None = None,
                    params: str | os.PathLike[str] | None = None,
                    expected: str | os.PathLike[str] | None = None, atol: float = 1e-9,
                    rtol: float = 0.0, max_differences: int = 20, namespace: str | None = None,
                    env: dict[str, str] | None = None, timeout: float = 10.0) -> ReplayResult:
    """Like :func:`nonfragile_tracker.bag.replay.replay`, through a tracker node over DDS.

    The inputs are those of :func:`~nonfragile_tracker.bag.replay.plan_replay` (same start,
    recovered initial speed and order as the in-process replay).

    Parameters
    ----------
    bag : path-like
        A real-time recording, or a lockstep one made with ``record_all`` (the reference
        samples are what is published).
    gains, params : path-like, optional
        Gain file and parameter file with a tracker section (defaults: the shipped ones).
    expected : path-like, optional
        Compare with this bag's ``cmd_vel`` instead of the recorded one.
    atol, rtol : float, optional
        Tolerance of the command comparison.
    max_differences : int, optional
        How many differing commands the result lists.
    namespace : str, optional
        The namespace of the bag's topics.
    env : dict, optional
        Base environment of the node process (:func:`.runner.reserved_domain`).
    timeout : float, optional
        Bound [s] of each wait for the node (start-up, discovery, each command).

    Returns
    -------
    ReplayResult

    Raises
    ------
    BagError
        For a lean lockstep recording (no reference samples to publish).
    RunError
        If the node dies or stays silent.
    """
    # the files read once: the node gets these values (the in-process prediction's too)
    config, values = load_tracker_parameters(gains, params)     # bad files: exit 2 first
    events = read_replay_events(bag, namespace=namespace)
    values = recorded_tuning(events, values)      # the node gets them as tuning_schedule
    if any(e.kind == 'trajectory' for e in events):
        raise BagError(f'{bag} is a lean lockstep recording (a trajectory message, no '
                       'reference samples): replay it in process (without --ros), or record '
                       'with --record-all / record_all:=true to replay it over DDS')
    plan = plan_replay(events, config, use_recorded=expected is None, values=values)
    mode = plan.mode
    predict = TrackerInputs(config, replay_rules(values, mode))
    with reserved_domain(env) as env, tempfile.TemporaryDirectory(prefix='nf_replay_') as tmp:
        pfile = write_parameter_file({'tracker': {'ros__parameters': values}},
                                     Path(tmp) / 'p.yaml')
        log = Path(tmp) / 'tracker.log'
        proc = NodeProcess('tracker', pfile, log, env,
                           ['-p', f'mode:={mode}', '-p', f'input_timeout:={NO_WATCHDOG}'])
        ctx = rclpy.Context()
        rclpy.init(context=ctx, domain_id=int(env['ROS_DOMAIN_ID']))
        node = rclpy.create_node('bag_replayer', context=ctx)
        got: list[Twist] = []
        sub = node.create_subscription(Twist, topics.CMD_VEL, got.append, DATA_QOS)
        pubs = {k: node.create_publisher(t, name, DATA_QOS) for k, (t, name) in _TYPES.items()}
        ex = rclpy.executors.SingleThreadedExecutor(context=ctx)
        ex.add_node(node)

        def wait(pred: Callable[[], bool], what: str) -> None:
            end = time.monotonic() + timeout
            while not pred():
                if proc.poll() is not None:
                    raise RunError(f'the tracker node exited ({proc.poll()}) during the '
                                   f'replay; its log:\n'
                                   f'{log.read_text(errors="replace")[-2000:]}')
                if time.monotonic() > end:
                    raise RunError(f'replay over DDS: no {what} within {timeout} s')
                ex.spin_once(timeout_sec=0.005)

        try:
            # matched both ways (our writers -> its readers, its writer -> our reader): a
            # command published before the match would be lost
            wait(lambda: all(p.get_subscription_count() >= 1 for p in pubs.values())
                 and sub.get_publisher_count() >= 1, 'tracker node matched on every topic')
            # a reliable reader may take a moment to accept a newly matched writer (its first
            # samples then come late, after a repair): let discovery settle both ways
            _spin_for(ex, SETTLE)
            commands = _publish_events(plan, predict, pubs, got, wait, ex)
        finally:
            node.destroy_node()
            rclpy.try_shutdown(context=ctx)
            proc.stop()
            proc.close()
    return finish_replay(bag, plan, commands, expected=expected, atol=atol, rtol=rtol,
                         max_differences=max_differences, via='over DDS (tracker node)')


def _spin_for(ex: Any, seconds: float) -> None:
    """Spin ``ex`` for ``seconds`` (discovery and matching settle meanwhile)."""
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        ex.spin_once(timeout_sec=0.01)


def _publish_events(plan: Any, predict: TrackerInputs, pubs: dict[str, Any],
                    got: list[Twist], wait: Callable[[Callable[[], bool], str], None],
                    ex: Any) -> list[tuple[int, Any]]:
    """Publish the plan's messages in order, each awaited command collected.

    After each message that the in-process rules expect a command for, the node's command
    is awaited.  Returns ``(receive_ns, Twist)`` pairs (the bag's type store's Twist).
    """
    ts = jazzy_typestore()
    RTwist, RVector3 = ts.types['geometry_msgs/msg/Twist'], ts.types['geometry_msgs/msg/Vector3']
    commands = []
    first_odom = True
    for e in (*plan.prime, *plan.events):
        if e.kind == 'odom' and first_odom:
            first_odom = False
            _spin_for(ex, 0.2 * SETTLE)                 # the state before the start
        before = len(got)
        out = predict.odom(e.msg) if e.kind == 'odom' else predict.reference(
            REF_INDEX[e.kind], e.msg)
        pubs[e.kind].publish(e.raw)
        if out is not None:
            wait(lambda: len(got) > before, f'command after {e.kind} at {e.receive_ns} ns')
            c = got[before]
            commands.append((e.receive_ns, RTwist(RVector3(c.linear.x, 0.0, 0.0),
                                                  RVector3(0.0, 0.0, c.angular.z))))
        else:
            # no command expected: the node's events executor handles messages in
            # arrival order, and one participant's samples arrive in publish order
            ex.spin_once(timeout_sec=0.0)
            if len(got) > before:
                raise RunError(f'the tracker node published a command after {e.kind} '
                               f'at {e.receive_ns} ns where the replay expects none')
    return commands
