"""Replay a recorded run into a fresh tracker and compare its commands with the recorded ones.

The recorded odometry and reference messages are fed, in bag order (the recorder's
receive order), to :class:`TrackerInputs` - the tracker node's input rules without
ROS - around the same step function as the node (:class:`control.loop.Tracker`):

* odometry in another frame than ``odom``, or with a stamp that does not advance, is
  ignored; a stamp jump above ``max_stamp_jump`` re-initialises the compensator;
* lockstep bags (most odometry stamps equal a reference stamp): a command when the
  odometry and the three reference parts with the same stamp are all in;
* real-time bags: a command at each odometry message with the latest reference parts
  (what the tracker had received by then).

Its commands are compared (:func:`compare.compare_messages`) with the recorded
``cmd_vel`` (Twist or TwistStamped) or with those of an ``expected`` bag: by index
when both have as many, else by time.  What the node does on its wall clock (the
real-time watchdog's stop commands after a silence) is not replayed: those recorded
stops show up as unpaired commands.

The DDS variant (through a real tracker node) is
:func:`nonfragile_tracker.nodes.replayer.replay_over_dds`.  No rclpy here.
"""
from __future__ import annotations

import math
import os
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from .. import topics
from ..control.gains import read_gain_file
from ..control.loop import Command, Tracker, TrackerConfig
from ..msgconv import pose_from_odom, reference_from_msgs, stamp_ns, tracker_config
from ..resources import config_dir
from ..runner import node_key
from .compare import Comparison, compare_messages, format_differences
from .reader import MissingTopicsError, open_reader, resolve_topics, typestore_for
from .writer import BagError, jazzy_typestore

__all__ = ['ReplayEvent', 'ReplayResult', 'TrackerInputs', 'TRACKER_DEFAULTS',
           'read_replay_events', 'load_tracker_parameters', 'replay', 'format_replay',
           'bag_mode', 'compare_commands', 'REF_INDEX']

#: The tracker node's defaults for the parameters the law uses (nodes/tracker.PARAMS;
#: a test keeps the two equal).
TRACKER_DEFAULTS: dict[str, Any] = {
    'K_shape': [2, 4], 'dt': 0.01, 'max_linear_speed': 1.0, 'max_angular_speed': 2.0,
    'min_speed': 1e-3, 'E': [1.0, 0.0, 0.0, 1.0], 'F': [0.5] * 8, 'Delta': [0.0] * 4,
    'delay_compensation': False,
    'A_tau': [0.01, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.02, 0.0, 0.0, 0.0, 0.0, 0.0],
    'tau': 0.2, 'max_stamp_jump': 1.0,
}
_KINDS = {topics.ODOM: 'odom', topics.REF_POSE: 'ref_pose', topics.REF_TWIST: 'ref_twist',
          topics.REF_ACCEL: 'ref_accel', topics.CMD_VEL: 'cmd'}
REF_INDEX = {'ref_pose': 0, 'ref_twist': 1, 'ref_accel': 2}


@dataclass(frozen=True)
class ReplayEvent:
    """One recorded input or command, in bag order."""

    kind: str                  # odom, ref_pose, ref_twist, ref_accel, cmd
    receive_ns: int
    topic: str
    msgtype: str
    raw: bytes                 # CDR bytes as recorded (published as is over DDS)
    msg: Any                   # deserialized (rosbags)


@dataclass
class ReplayResult:
    """What a replay produced and how it compares."""

    bag: Path
    mode: str                                  # lockstep or realtime
    commands: list[tuple[int, Any]]            # (receive ns of the triggering input, Twist)
    recorded: list[tuple[int, Any]]            # the commands compared against
    comparison: Comparison
    inputs: dict[str, int] = field(default_factory=dict)   # events fed per kind
    ignored: dict[str, int] = field(default_factory=dict)  # why inputs were ignored
    reference: str = 'recorded'                # or the expected bag's path
    via: str = 'in process'

    @property
    def max_abs_error(self) -> float:
        return max(self.comparison.max_abs_error.values(), default=math.nan)


def read_replay_events(path: str | os.PathLike, *, namespace: str | None = None
                       ) -> list[ReplayEvent]:
    """Odometry, reference parts and commands of a bag, in bag (receive) order."""
    reader = open_reader(path)
    try:
        by_topic = {c.topic: c for c in reader.connections}
        tmap = resolve_topics(by_topic, list(_KINDS), namespace)
        missing = [n for n in (topics.ODOM, topics.REF_POSE, topics.REF_TWIST,
                               topics.REF_ACCEL) if n not in tmap]
        if missing:
            raise MissingTopicsError(
                f'bag {path} lacks {", ".join(missing)}: a replay feeds the recorded odometry '
                f'and reference to the tracker (the bag has {sorted(by_topic) or "no topics"})',
                missing)
        kinds = {tmap[n]: k for n, k in _KINDS.items() if n in tmap}
        ts = typestore_for(reader)
        conns = [c for c in reader.connections if c.topic in kinds]
        out = []
        try:
            for conn, t, raw in reader.messages(connections=conns):
                out.append(ReplayEvent(kinds[conn.topic], int(t), conn.topic, conn.msgtype,
                                       bytes(raw), ts.deserialize_cdr(raw, conn.msgtype)))
        except (ValueError, IndexError, KeyError, AssertionError) as exc:
            raise BagError(f'{path}: a message cannot be read ({type(exc).__name__}: {exc}); '
                           'try `nonfragile_tracker bag repair`') from None
    finally:
        reader.close()
    return out


def bag_mode(events: Iterable[ReplayEvent]) -> str:
    """``lockstep`` when at least half the odometry stamps equal a reference stamp."""
    odom, ref = set(), set()
    for e in events:
        if e.kind == 'odom':
            odom.add(stamp_ns(e.msg.header.stamp))
        elif e.kind == 'ref_pose':
            ref.add(stamp_ns(e.msg.header.stamp))
    return 'lockstep' if odom and len(odom & ref) >= 0.5 * len(odom) else 'realtime'


class TrackerInputs:
    """The tracker node's input rules (frames, stamps, lockstep/real-time triggering), ROS-free.

    ``odom(msg)`` and ``reference(i, msg)`` take messages (rclpy or rosbags) and return
    the :class:`Command` the node would publish, or None.  ``ignored`` counts what was
    ignored and why.
    """

    def __init__(self, config: TrackerConfig, mode: str = 'realtime',
                 max_stamp_jump: float = TRACKER_DEFAULTS['max_stamp_jump']):
        if mode not in ('lockstep', 'realtime'):
            raise BagError(f'mode must be lockstep or realtime, got {mode!r}')
        self.tracker = Tracker(config)
        self.mode = mode
        self.max_jump_ns = max_stamp_jump * 1e9
        self._odom = None
        self._ref: list[Any] = [None, None, None]
        self.last_stamp = -1
        self.last_odom_stamp = -1
        self.ignored: dict[str, int] = {}
        self.jumps = 0

    def _ignore(self, why: str) -> None:
        self.ignored[why] = self.ignored.get(why, 0) + 1

    def odom(self, msg) -> Command | None:
        if msg.header.frame_id != topics.ODOM_FRAME:
            return self._ignore(f'odom frame {msg.header.frame_id!r} is not '
                                f'{topics.ODOM_FRAME!r}')
        s = stamp_ns(msg.header.stamp)
        if s <= self.last_odom_stamp:
            return self._ignore('odom stamp not advancing') if s < self.last_odom_stamp \
                else None
        if self.last_odom_stamp >= 0 and s - self.last_odom_stamp > self.max_jump_ns:
            self.jumps += 1
            self.tracker.reset()
        self._odom = msg
        self.last_odom_stamp = s
        return self._compute()

    def reference(self, i: int, msg) -> Command | None:
        if msg.header.frame_id != topics.ODOM_FRAME:
            return self._ignore(f'reference frame {msg.header.frame_id!r}')
        self._ref[i] = msg
        return self._compute() if self.mode == 'lockstep' else None

    def _compute(self) -> Command | None:
        odom = self._odom
        if odom is None or any(r is None for r in self._ref):
            return None
        s = stamp_ns(odom.header.stamp)
        if self.mode == 'lockstep' and (s <= self.last_stamp or any(
                stamp_ns(r.header.stamp) != s for r in self._ref)):
            return None
        pose = pose_from_odom(odom.pose.pose)
        if isinstance(pose, str):
            self._odom = None
            return self._ignore(f'odom: {pose}')
        ref = reference_from_msgs(stamp_ns(self._ref[0].header.stamp) * 1e-9, *self._ref)
        if isinstance(ref, str):
            return self._ignore(ref)
        self.last_stamp = s
        speed = odom.twist.twist.linear.x
        return self.tracker.step(pose[0], pose[1], pose[2], ref,
                                 measured_speed=speed if math.isfinite(speed) else 0.0)


def _param_section(path: Path) -> dict:
    try:
        data = yaml.safe_load(Path(path).read_text()) or {}
    except OSError as exc:
        raise BagError(f'cannot read parameter file {path}: {exc.strerror or exc}') from None
    except yaml.YAMLError as exc:
        raise BagError(f'{path} is not valid YAML: {exc}') from None
    if not isinstance(data, dict):
        raise BagError(f'{path}: expected a ROS 2 parameter file (node: ros__parameters: ...)')
    for key, section in data.items():
        if node_key(str(key)) in ('tracker', '**') and isinstance(section, dict):
            return dict(section.get('ros__parameters') or {})
    return {}


def load_tracker_parameters(gains: str | os.PathLike | None = None,
                            params: str | os.PathLike | None = None
                            ) -> tuple[TrackerConfig, dict]:
    """Tracker config and parameter values from a gain file and a parameter file.

    Defaults: ``config/tracker_gains.yaml`` and ``config/paper_scenario.yaml``; values
    absent from both are the node's defaults (:data:`TRACKER_DEFAULTS`).
    """
    gains = Path(gains) if gains is not None else config_dir() / 'tracker_gains.yaml'
    params = Path(params) if params is not None else config_dir() / 'paper_scenario.yaml'
    values = dict(TRACKER_DEFAULTS)
    values.update(_param_section(params))
    K = read_gain_file(gains)
    values['K'] = [float(v) for v in np.asarray(K).ravel()]
    values['K_shape'] = list(np.asarray(K).shape)
    return tracker_config(values), values


def _twist(msg) -> Any:
    return msg.twist if hasattr(msg, 'header') else msg


def compare_commands(commands: list[tuple[int, Any]], recorded: list[tuple[int, Any]], *,
                     atol: float = 1e-9, rtol: float = 0.0, max_differences: int = 20,
                     time_tolerance: float | None = None) -> Comparison:
    """Replayed vs recorded commands (``cmd_vel``): by index when both have as many,
    else by time (receive time of the triggering input vs the recorded receive time)."""
    a = [(t, _twist(m)) for t, m in recorded]
    align = 'index' if len(a) == len(commands) else 'time'
    if time_tolerance is None:
        tt = np.diff([t for t, _ in commands]) * 1e-9
        time_tolerance = 0.5 * float(np.median(tt)) if tt.size else 0.005
    return compare_messages({topics.CMD_VEL: a}, {topics.CMD_VEL: commands}, atol=atol,
                            rtol=rtol, align=align, time_tolerance=time_tolerance,
                            expected_start_ns=0, got_start_ns=0,
                            max_differences=max_differences)


def replay(bag: str | os.PathLike, *, gains: str | os.PathLike | None = None,
           params: str | os.PathLike | None = None, expected: str | os.PathLike | None = None,
           atol: float = 1e-9, rtol: float = 0.0, max_differences: int = 20,
           namespace: str | None = None) -> ReplayResult:
    """Feed a bag's odometry and reference to a fresh tracker in process; compare commands.

    Parameters
    ----------
    bag : path-like
        A recorded run (lockstep or real time) with ``odom`` and the reference topics.
    gains, params : path-like, optional
        Gain file and parameter file with a tracker section (defaults: the shipped ones).
    expected : path-like, optional
        Compare with this bag's ``cmd_vel`` instead of the recorded one.
    atol, rtol : float
        Tolerance of the command comparison.

    Returns
    -------
    ReplayResult
        ``comparison.equal`` tells whether the commands are reproduced.
    """
    config, values = load_tracker_parameters(gains, params)
    events = read_replay_events(bag, namespace=namespace)
    mode = bag_mode(events)
    inputs = TrackerInputs(config, mode, float(values['max_stamp_jump']))
    ts = jazzy_typestore()
    Twist, Vector3 = ts.types['geometry_msgs/msg/Twist'], ts.types['geometry_msgs/msg/Vector3']
    commands, recorded, fed = [], [], {}
    for e in events:
        fed[e.kind] = fed.get(e.kind, 0) + 1
        if e.kind == 'cmd':
            recorded.append((e.receive_ns, e.msg))
            continue
        cmd = inputs.odom(e.msg) if e.kind == 'odom' else inputs.reference(
            REF_INDEX[e.kind], e.msg)
        if cmd is not None:
            commands.append((e.receive_ns, Twist(Vector3(float(cmd.v), 0.0, 0.0),
                                                 Vector3(0.0, 0.0, float(cmd.w)))))
    source = 'recorded'
    if expected is not None:
        recorded = [(e.receive_ns, e.msg) for e in read_replay_events(expected)
                    if e.kind == 'cmd']
        source = str(expected)
    if not recorded:
        raise MissingTopicsError(f'{expected or bag} has no {topics.CMD_VEL} to compare the '
                                 'replayed commands with', [topics.CMD_VEL])
    cmp = compare_commands(commands, recorded, atol=atol, rtol=rtol,
                           max_differences=max_differences)
    return ReplayResult(Path(bag), mode, commands, recorded, cmp, fed, dict(inputs.ignored),
                        source)


def format_replay(res: ReplayResult) -> str:
    """Summary of a replay: inputs fed, commands produced and the comparison."""
    fed = ', '.join(f'{k} {n}' for k, n in sorted(res.inputs.items()))
    lines = [f'replay of {res.bag} ({res.mode}) {res.via}: fed {fed}',
             f'commands: {len(res.commands)} replayed, {len(res.recorded)} '
             f'{"recorded" if res.reference == "recorded" else "in " + res.reference}']
    lines += [f'ignored: {why} ({n})' for why, n in res.ignored.items()]
    if res.comparison.equal:
        lines.append(f'commands reproduced: max |diff| {res.max_abs_error:.3g} '
                     f'({res.comparison.summary[topics.CMD_VEL].align} alignment)')
    else:
        lines.append('commands differ:')
        lines.append(format_differences(res.comparison))
    return '\n'.join(lines)
