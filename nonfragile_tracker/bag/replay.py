"""Replay a recorded run into a fresh tracker and compare its commands with the recorded ones.

The recorded odometry and reference (or trajectory) messages are fed to
:class:`~nonfragile_tracker.interface.tracker_inputs.TrackerInputs` - the tracker node's own input
rules, ROS-free - with the tracker's parameters (:func:`replay_rules`), in stamp order for
a lockstep bag and in the recorder's order for a real-time one (:func:`plan_replay`), and
its commands are compared (:func:`~.compare.compare_messages`) with the recorded ones or
an expected bag's.  The DDS variant (through a real tracker node) is
:func:`nonfragile_tracker.workflows.dds_replay.replay_over_dds`.  No rclpy here.

See doc/bags.md, section "``bag replay``" (the feeding order, real-time bags, lean bags).
"""
from __future__ import annotations

import bisect
import copy
import math
import os
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from ..interface import topics
from ..control.simulation.gains import gain_from_file_data
from ..control.simulation.tracker import Command, TrackerConfig
from ..control.identification.tuning import format_script, parse_script
from ..control.simulation.timing import WINDOW
from ..files import node_key
from ..interface.msgconv import LAW_DEFAULTS, stamp_ns, tracker_config
from ..interface.resources import config_dir
# the tracker's input rules: one home, shared with the tracker node
from ..interface.tracker_inputs import INPUT_DEFAULTS, InputRules, Step, TrackerInputs, input_rules
from .compare import Comparison, compare_messages, format_differences
from .reader import MissingTopicsError, open_reader, resolve_topics, typestore_for
from .errors import BagError
from .typestore import jazzy_typestore

__all__ = ['ReplayEvent', 'ReplayResult', 'TrackerInputs', 'TRACKER_DEFAULTS',
           'read_replay_events', 'load_tracker_parameters', 'replay', 'format_replay',
           'bag_mode', 'compare_commands', 'REF_INDEX', 'ReplayPlan', 'plan_replay',
           'finish_replay', 'ORDER_WINDOW', 'START_SEARCH', 'START_CHECK', 'PRIME_SEARCH',
           'replay_rules', 'recorded_tuning']

#: The tracker node's defaults for the parameters the replay uses (the law's, then the
#: input rules'; nodes/tracker.PARAMS: a test keeps the two equal).
TRACKER_DEFAULTS: dict[str, Any] = {**LAW_DEFAULTS, 'min_turning_radius': 0.0, **INPUT_DEFAULTS}
#: A command as replayed or recorded: (receive ns of its input, Twist or TwistStamped).
Timed = tuple[int, Any]
_KINDS = {topics.ODOM: 'odom', topics.REF_POSE: 'ref_pose', topics.REF_TWIST: 'ref_twist',
          topics.REF_ACCEL: 'ref_accel', topics.CMD_VEL: 'cmd'}
REF_INDEX = {'ref_pose': 0, 'ref_twist': 1, 'ref_accel': 2}
#: Trajectory messages a lean lockstep bag carries instead of the reference samples
#: (kind ``trajectory``), preferred in this order.
_TRAJECTORY_TOPICS = (topics.TRAJECTORY_MULTIDOF, topics.TRAJECTORY)


@dataclass(frozen=True)
class ReplayEvent:
    """One recorded input or command, in bag order."""

    kind: str                  # odom, ref_pose, ref_twist, ref_accel, cmd, trajectory,
                               # followed (tracker/trajectory: not fed, says where adopted),
                               # tuning (tracker/tuning: not fed, the tracker's retunes)
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
    plan: Any = None                           # the ReplayPlan behind it

    @property
    def max_abs_error(self) -> float:
        """Largest absolute command difference over the compared fields (nan if none)."""
        return max(self.comparison.max_abs_error.values(), default=math.nan)


def read_replay_events(path: str | os.PathLike[str], *, namespace: str | None = None
                       ) -> list[ReplayEvent]:
    """Odometry, reference parts and commands of a bag, in bag (receive) order.

    Also the trajectory message (``trajectory_multidof``, else ``trajectory``) when the
    bag has one (kind ``trajectory``; the per-step samples are then not fed), the
    tracker's ``tracker/trajectory`` announcements (kind ``followed``) and its retunes
    (``tracker/tuning``, kind ``tuning``: :func:`recorded_tuning`).

    Parameters
    ----------
    path : path-like
        The bag.
    namespace : str, optional
        The namespace of the run's topics (default: found from the bag).

    Returns
    -------
    list of ReplayEvent

    Raises
    ------
    MissingTopicsError
        If the bag lacks odometry or the reference (or trajectory message).
    BagError
        If a message cannot be read.
    """
    reader = open_reader(path)
    try:
        by_topic = {c.topic: c for c in reader.connections}
        tmap = resolve_topics(by_topic, list(_KINDS) + list(_TRAJECTORY_TOPICS)
                              + [topics.FOLLOWED_TRAJECTORY, topics.TUNING], namespace)
        missing = [n for n in (topics.ODOM, topics.REF_POSE, topics.REF_TWIST,
                               topics.REF_ACCEL) if n not in tmap]
        lean = [n for n in _TRAJECTORY_TOPICS if n in tmap]
        if missing and lean and topics.ODOM in tmap:
            missing = []                   # a lean lockstep bag: the trajectory message
        if missing:
            raise MissingTopicsError(
                f'bag {path} lacks {", ".join(missing)}: a replay feeds the recorded odometry '
                'and reference (or trajectory message) to the tracker (the bag has '
                f'{sorted(by_topic) or "no topics"})', missing)
        kinds = {tmap[n]: k for n, k in _KINDS.items() if n in tmap}
        if lean:
            # the tracker follows a trajectory message whenever it has one (lockstep or real
            # time, lean or full recording): feed that, not the per-step samples
            kinds[tmap[lean[0]]] = 'trajectory'
            if topics.FOLLOWED_TRAJECTORY in tmap:
                # where the tracker adopted it (the odometry stamp of its first command)
                kinds[tmap[topics.FOLLOWED_TRAJECTORY]] = 'followed'
        if topics.TUNING in tmap:
            kinds[tmap[topics.TUNING]] = 'tuning'
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


def recorded_tuning(events: Iterable[ReplayEvent], values: Mapping[str, Any]
                    ) -> dict[str, Any]:
    """``values`` with the retunes the bag recorded as the ``tuning_schedule``.

    A tracker with ``monitor_tune`` tunes its predictor from its own commands and odometry
    since it started; a recording that joined it later lacks them, so the replay applies
    the retunes the tracker published (``tracker/tuning``, each at the odometry stamp it took
    effect at) instead of estimating them again.  Without tuning messages, or with the
    tuning off (or a schedule given), ``values`` unchanged.

    Parameters
    ----------
    events : iterable of ReplayEvent
        A bag's events (:func:`read_replay_events`).
    values : mapping
        The tracker's parameter values.

    Returns
    -------
    dict
    """
    out = dict(values)
    v = {**TRACKER_DEFAULTS, **out}
    if not (v['monitor'] and v['monitor_tune']) or v.get('tuning_schedule'):
        return out
    script = sorted({(stamp_ns(e.msg.header.stamp), float(e.msg.vector.x),
                      float(e.msg.vector.y), float(e.msg.vector.z))
                     for e in events if e.kind == 'tuning'})
    if script:
        out['tuning_schedule'] = format_script(script)
    return out


def bag_mode(events: Iterable[ReplayEvent]) -> str:
    """``lockstep`` when at least half the odometry stamps equal a reference stamp.

    Parameters
    ----------
    events : iterable of ReplayEvent
        A bag's events.

    Returns
    -------
    str
        ``lockstep`` or ``realtime``.
    """
    odom, ref = set(), set()
    for e in events:
        if e.kind == 'odom':
            odom.add(stamp_ns(e.msg.header.stamp))
        elif e.kind == 'ref_pose':
            ref.add(stamp_ns(e.msg.header.stamp))
    return 'lockstep' if odom and len(odom & ref) >= 0.5 * len(odom) else 'realtime'


def _plan_follow(events: list[ReplayEvent], config: TrackerConfig, recorded: list[Timed],
                 fed: dict[str, int], values: Mapping[str, Any]) -> ReplayPlan:
    """A bag with a trajectory message: the trajectory message(s) and odometry, in bag order.

    Real time (one trajectory message, recorded commands): the tracker adopted the
    trajectory at some odometry after the one the recorder saw before it (seconds later
    when it re-timed it in its worker thread).  The tracker says at which: the first
    ``tracker/trajectory`` it published after it is stamped with that odometry's stamp, and
    the trajectory is adopted right before the odometry with that stamp (no command before
    it).  A bag without it (an older tracker), or whose recorder missed that odometry, gets
    the placement from which the first :data:`START_CHECK` recorded commands are reproduced
    (searched up to :data:`FOLLOW_SEARCH` odometry messages after the bag's; ambiguous when
    they are the zeros of a wait for a future start stamp), else bag order.
    """
    built: dict[int, Any] = {}        # each message built (and re-timed) once

    def run(order: list[ReplayEvent], defer: bool, limit: int | None = None
            ) -> tuple[TrackerInputs, list[Timed]]:
        inputs = TrackerInputs(config, rules)
        inputs.cache = built
        commands: list[Timed] = []
        for e in order:
            if e.kind == 'odom':
                step = inputs.odom(e.msg)
            else:
                kind = 'path' if e.msgtype == 'nav_msgs/msg/Path' else 'multidof'
                step = inputs.trajectory(e.msg, kind, e.topic, defer=defer)
            if step is not None:
                commands.append((e.receive_ns, _twist_msg(step.command)))
                if limit is not None and len(commands) >= limit:
                    break
        return inputs, commands

    data = [e for e in events if e.kind in ('odom', 'trajectory')]
    trajs = [i for i, e in enumerate(data) if e.kind == 'trajectory']
    # lockstep: the reference samples' stamps (full bags) or odometry on an exact grid
    # (lean bags: sim time, one stamp per step); real time: jittery wall-clock stamps
    steps = np.diff([stamp_ns(e.msg.header.stamp) for e in data if e.kind == 'odom'])
    mode = 'lockstep' if bag_mode(events) == 'lockstep' or (
        steps.size and int(steps.max() - steps.min()) <= 1000) else 'realtime'
    rules = replay_rules(values, mode)
    if mode == 'realtime' and len(trajs) == 1 and recorded:
        ti = trajs[0]
        rest = data[:ti] + data[ti + 1:]
        adopted = next((stamp_ns(e.msg.header.stamp) for e in events if e.kind == 'followed'),
                       None)
        at = next((p for p, e in enumerate(rest) if e.kind == 'odom'
                   and stamp_ns(e.msg.header.stamp) == adopted), None)
        if at is not None:
            order = rest[:at] + [data[ti]] + rest[at:]
            inputs, commands = run(order, True)
            return ReplayPlan('realtime', order, commands, recorded, fed,
                              dict(inputs.ignored), adopted_ns=adopted)
    if mode == 'realtime' and len(trajs) == 1 and len(recorded) >= START_CHECK:
        ti = trajs[0]
        rest = data[:ti] + data[ti + 1:]
        check = recorded[:START_CHECK]
        for defer in (False, True):
            for p in range(max(ti - 5, 0), min(ti + FOLLOW_SEARCH, len(rest)) + 1):
                order = rest[:p] + [data[ti]] + rest[p:]
                _, cmds = run(order, defer, START_CHECK)
                if len(cmds) == START_CHECK and all(
                        _agrees_twist(c, r, 1e-9) for (_, c), (_, r) in zip(cmds, check)):
                    inputs, commands = run(order, defer)
                    return ReplayPlan('realtime', order, commands, recorded, fed,
                                      dict(inputs.ignored))
    inputs, commands = run(data, False)
    return ReplayPlan(mode, data, commands, recorded, fed, dict(inputs.ignored))


#: Real-time follower bags: odometry messages after the bag's position of the trajectory
#: message at which the tracker may have adopted it (a re-timing of about 1-3 s).
FOLLOW_SEARCH = 250


def _agrees_twist(a: Any, b: Any, atol: float) -> bool:
    ta, tb = _twist(a), _twist(b)
    return bool(abs(ta.linear.x - tb.linear.x) <= atol
                and abs(ta.angular.z - tb.angular.z) <= atol)


def _read_parameter_file(path: Path) -> dict[str, Any]:
    try:
        data = yaml.safe_load(Path(path).read_text()) or {}
    except OSError as exc:
        raise BagError(f'cannot read parameter file {path}: {exc.strerror or exc}') from None
    except yaml.YAMLError as exc:
        raise BagError(f'{path} is not valid YAML: {exc}') from None
    if not isinstance(data, dict):
        raise BagError(f'{path}: expected a ROS 2 parameter file (node: ros__parameters: ...)')
    return data


def _tracker_section(data: dict[str, Any]) -> dict[str, Any]:
    for key, section in data.items():
        if node_key(str(key)) in ('tracker', '**') and isinstance(section, dict):
            return dict(section.get('ros__parameters') or {})
    return {}


def load_tracker_parameters(gains: str | os.PathLike[str] | None = None,
                            params: str | os.PathLike[str] | None = None
                            ) -> tuple[TrackerConfig, dict[str, Any]]:
    """Tracker config and parameter values from a gain file and a parameter file.

    Defaults: ``config/tracker_gains.yaml`` and ``config/paper_scenario.yaml``; values
    absent from both are the node's defaults (:data:`TRACKER_DEFAULTS`).  The gain file's
    other tracker parameters (the predictor of a ``latency-design`` file) override the
    parameter file's, as ``run --gains`` does.

    Parameters
    ----------
    gains : path-like, optional
        A gain file (``synthesize`` / ``latency-design`` output).
    params : path-like, optional
        A ROS 2 parameter file with a tracker section.

    Returns
    -------
    (TrackerConfig, dict)
        The law's configuration and every tracker parameter value by name.

    Raises
    ------
    BagError
        If a file cannot be read; an InputError for a bad gain or value.
    """
    gains = Path(gains) if gains is not None else config_dir() / 'tracker_gains.yaml'
    params = Path(params) if params is not None else config_dir() / 'paper_scenario.yaml'
    values = dict(TRACKER_DEFAULTS)
    values.update(_tracker_section(_read_parameter_file(params)))
    # the gain file's tracker section overrides the parameter file, as in a run
    # (`run --gains`, scenario_parameters): a latency-design gain file carries the
    # predictor parameters its gain was designed with.  Read once: K from the same content
    gain_file = _read_parameter_file(gains)
    values.update({k: v for k, v in _tracker_section(gain_file).items()
                   if k not in ('K', 'K_shape')})
    K = gain_from_file_data(gain_file or None, gains)       # (empty: None, as read)
    values['K'] = [float(v) for v in np.asarray(K).ravel()]
    values['K_shape'] = list(np.asarray(K).shape)
    return tracker_config(values), values


def _twist(msg: Any) -> Any:
    return msg.twist if hasattr(msg, 'header') else msg


def compare_commands(commands: list[tuple[int, Any]], recorded: list[tuple[int, Any]], *,
                     atol: float = 1e-9, rtol: float = 0.0, max_differences: int = 20,
                     time_tolerance: float | None = None) -> Comparison:
    """Replayed vs recorded commands (``cmd_vel``).

    By index when both have as many, else by time (receive time of the triggering input
    vs the recorded receive time).

    Parameters
    ----------
    commands : list of (int, Twist)
        Replayed commands with the receive time (ns) of their input.
    recorded : list of (int, Twist or TwistStamped)
        Recorded commands with their receive time (ns).
    atol, rtol : float, optional
        Tolerance of the comparison.
    max_differences : int, optional
        How many differing commands are listed.
    time_tolerance : float, optional
        Time alignment: how far apart (s) a pair may be; default half the median
        interval of the replayed commands.

    Returns
    -------
    Comparison
    """
    a = [(t, _twist(m)) for t, m in recorded]
    align = 'index' if len(a) == len(commands) else 'time'
    if time_tolerance is None:
        tt = np.diff([t for t, _ in commands]) * 1e-9
        time_tolerance = 0.5 * float(np.median(tt)) if tt.size else 0.005
    return compare_messages({topics.CMD_VEL: a}, {topics.CMD_VEL: commands}, atol=atol,
                            rtol=rtol, align=align, time_tolerance=time_tolerance,
                            expected_start_ns=0, got_start_ns=0,
                            max_differences=max_differences)


@dataclass
class ReplayPlan:
    """What to feed the tracker, in which order, and what it should answer.

    ``events`` are the inputs in the order the tracker saw them (bag order, with any
    swap the recorded commands showed); ``commands`` the in-process answers, with the
    time of the triggering input; ``initial_speed`` the compensator speed recovered
    from the first recorded command (real-time bags), also written into the first
    odometry event's twist so a tracker node starts from it.
    """

    mode: str
    events: list[ReplayEvent]
    commands: list[tuple[int, Any]]
    recorded: list[tuple[int, Any]]
    fed: dict[str, int]
    ignored: dict[str, int]
    initial_speed: float | None = None
    skipped_inputs: int = 0          # inputs before the tracker's first recorded command
    swaps: int = 0                   # odometry/reference pairs taken in the other order
    adopted_ns: int | None = None    # real-time follower bags: the odometry stamp at which
                                     # the tracker said (tracker/trajectory) it adopted it
    #: real-time bags that join a run: the odometry before the start, fed first without a
    #: reference (no command) so the tracker's period estimate is the running tracker's
    prime: tuple[ReplayEvent, ...] = ()
    #: why the recorded commands cannot be reproduced, when the replay can tell
    note: str = ''


#: Receive-time window (s): a reference the recorder got this long after a command may have
#: reached the tracker before it computed the command (and at the start, before the first
#: odometry).
ORDER_WINDOW = 0.002


def _with_speed(e: ReplayEvent, v: float) -> ReplayEvent:
    msg = copy.deepcopy(e.msg)
    msg.twist.twist.linear.x = float(v)
    raw = bytes(jazzy_typestore().serialize_cdr(msg, e.msgtype))
    return ReplayEvent(e.kind, e.receive_ns, e.topic, e.msgtype, raw, msg)


def _prime_timing(inputs: TrackerInputs, before: list[ReplayEvent], count: int
                  ) -> list[ReplayEvent]:
    """The odometry period the tracker had measured when the recording joined the run.

    The tracker takes its step from the odometry stamps (``dt`` 0) and measures them while
    no step is due (:meth:`TrackerInputs.compute`): a replay that starts at its first
    recorded command feeds it the last ``count`` odometry messages before it, without a
    reference, as the running tracker had them (:mod:`control.simulation.timing`; a
    tracker that ran for a while had a whole window, one that had just started fewer).
    Returns those events: a tracker node is fed the same first (:attr:`ReplayPlan.prime`).
    """
    prime = before[max(0, len(before) - count):]
    for e in prime:
        inputs.odom(e.msg)
    return prime


def _recover_speed(inputs: TrackerInputs, odom: ReplayEvent, target_v: float) -> float | None:
    """The compensator speed v at which the tracker's command speed is ``target_v``.

    The command speed ``(v + v_next) / 2`` is affine in v (``v_next = v + a dt`` with
    ``a`` affine in v) unless saturated: two trials give the line, a third checks it.
    """
    def f(v: float) -> float | None:
        trial = inputs.fork()
        trial.tracker.reset(v)
        step = trial.odom(odom.msg)
        return None if step is None else step.command.v
    f0, f1 = f(0.0), f(1.0)
    if f0 is None or f1 is None or f1 == f0:
        return None
    v = (target_v - f0) / (f1 - f0)
    got = f(v)
    return v if got is not None and abs(got - target_v) <= 1e-12 * max(1.0, abs(v)) else None


def _twist_msg(cmd: Command) -> Any:
    ts = jazzy_typestore()
    Twist, Vector3 = ts.types['geometry_msgs/msg/Twist'], ts.types['geometry_msgs/msg/Vector3']
    return Twist(Vector3(float(cmd.v), 0.0, 0.0), Vector3(0.0, 0.0, float(cmd.w)))


def _deviation(cmd: Command, rec: Any) -> float:
    """The larger of the speed and yaw-rate differences between a command and a recorded one."""
    tw = _twist(rec)
    return float(max(abs(cmd.v - tw.linear.x), abs(cmd.w - tw.angular.z)))


def _agrees(cmd: Command, rec: Any, atol: float) -> bool:
    return bool(_deviation(cmd, rec) <= atol)


#: A command reproduced to this many units of round-off (relative to the larger of 1 and the
#: command's speed and yaw rate) is
#: the tracker's own: no other reference state is tried for it (the replay's start,
#: recovered from the first recorded command, may differ from the tracker's in the last bits).
ROUND_OFF = 64 * np.finfo(float).eps
#: How far back (s) before the first recorded command the tracker's first input may lie
#: (a tracker may process a burst of queued inputs when it starts).
START_SEARCH = 1.0
#: Recorded commands that must be reproduced to accept a starting point.
START_CHECK = 10
#: How much later (s) the recorder may have received an odometry message than the tracker
#: did (starts that make a command come before its odometry by more are tried last).
START_SKEW = 0.02
#: At the nearest this many starting points the replay also tries a tracker that had
#: measured some but not a whole window of odometry intervals (it had just started: its
#: first reference came a few odometry messages after its first); at every start it tries
#: a whole window and none.
PRIME_SEARCH = 3


def replay_rules(values: Mapping[str, Any] | None, mode: str) -> InputRules:
    """The tracker's input rules for a replay: its parameters, the bag's mode.

    The replay applies the rules the tracker ran with: its ``odom_frame`` (the node's
    configurable frame, from the parameter file; default ``odom``), ``max_stamp_jump``,
    trajectory time law, start rule and limits.  ``wait_for_trajectory`` is off: a bag
    with a trajectory message is fed that message (and no samples), one without it was
    recorded from a tracker following the samples.

    Parameters
    ----------
    values : mapping or None
        The tracker's parameter values (:func:`load_tracker_parameters`); missing names
        take :data:`TRACKER_DEFAULTS`.
    mode : str
        ``lockstep`` or ``realtime`` (:func:`bag_mode`).

    Returns
    -------
    InputRules
    """
    return input_rules({**TRACKER_DEFAULTS, **(values or {}), 'wait_for_trajectory': False},
                       mode)


def plan_replay(events: list[ReplayEvent], config: TrackerConfig, *,
                max_stamp_jump: float | None = None, use_recorded: bool = True,
                atol: float = 1e-9, values: Mapping[str, Any] | None = None) -> ReplayPlan:
    """Run the tracker over the events in process and fix what the recorder cannot tell.

    Lockstep bags are fed in stamp order, any other bag compared with another bag
    (``use_recorded`` False) in bag order.  A real-time bag compared with its own commands is
    fed as the tracker saw it, which the recorder (another reader, with its own timing)
    shows only approximately:

    * the start: the tracker may have started, or the recorder may have joined, after
      the first inputs; the replay starts at the odometry (within :data:`START_SEARCH`
      s before the first recorded command) from which :data:`START_CHECK` recorded
      commands are reproduced, with the compensator speed recovered from the first and
      the odometry the tracker had measured its period on before it (a whole window, or
      none: a tracker whose first odometry made its first step; at the nearest
      :data:`PRIME_SEARCH` starts any number between);
    * the reference at each odometry: the tracker uses the latest reference parts it
      has; when the bag order's choice does not reproduce the recorded command, the
      other reference states are tried, from the one used at the previous command up to
      those received :data:`ORDER_WINDOW` s after the command (the tracker and the
      recorder are two readers: under load one got the odometry before a reference the
      other got first, by several milliseconds; or a burst of queued odometry was
      processed late).

    Every odometry after the start is paired with the next recorded command; once a
    command cannot be reproduced this way, the rest is fed in bag order (and the
    comparison shows the difference).

    A bag with a trajectory message (``trajectory_multidof`` or ``trajectory``: the tracker
    follows it whenever it has one; lockstep or real time, lean or full) is fed that
    message and the odometry in bag order.

    The rules are the tracker's
    (:class:`~nonfragile_tracker.interface.tracker_inputs.TrackerInputs`, :func:`replay_rules`).

    Parameters
    ----------
    events : list of ReplayEvent
        A bag's events (:func:`read_replay_events`).
    config : TrackerConfig
        The law (:func:`load_tracker_parameters`).
    max_stamp_jump : float, optional
        Overrides ``values['max_stamp_jump']``.
    use_recorded : bool, optional
        The bag's own commands are the comparison (a real-time bag is then fed as the
        tracker saw it, see above); False: fed in bag order.
    atol : float, optional
        Tolerance with which a recorded command counts as reproduced.
    values : mapping, optional
        The tracker's parameter values: the input rules (:func:`replay_rules`).

    Returns
    -------
    ReplayPlan
    """
    recorded = [(e.receive_ns, e.msg) for e in events if e.kind == 'cmd']
    fed: dict[str, int] = {}
    for e in events:
        if e.kind not in ('followed', 'tuning'):
            fed[e.kind] = fed.get(e.kind, 0) + 1
    values = {**(values or {})}
    if max_stamp_jump is not None:
        values['max_stamp_jump'] = max_stamp_jump
    if 'trajectory' in fed:
        return _plan_follow(events, config, recorded, fed, values)
    mode = bag_mode(events)
    data = [e for e in events if e.kind not in ('cmd', 'followed', 'tuning')]
    note = ''
    if use_recorded and mode == 'realtime' and recorded:
        # a retune at or before the odometry of the first recorded command: the predictor it
        # made held commands the bag lacks (no start reproduces it; none is searched)
        script = parse_script(values.get('tuning_schedule') or '')
        start = [stamp_ns(e.msg.header.stamp) for e in data
                 if e.kind == 'odom' and e.receive_ns <= recorded[0][0]][-1:]
        if script and start and script[0][0] <= start[0]:
            note = (f'the tracker tuned its predictor (tracker/tuning, at the odometry '
                    f'stamped {script[0][0] * 1e-9:.6f} s) before its first recorded command: '
                    'the state of its predictor then (the commands it had sent) is not in the '
                    'bag, so its commands cannot be reproduced exactly; fed in bag order')
        else:
            plan = _plan_realtime(data, recorded, config, replay_rules(values, mode), atol)
            if plan is not None:
                plan.fed = fed
                return plan
    if mode == 'lockstep':
        # a lockstep step is defined by its stamp, not by the recorder's receive order: the
        # reference publishes its samples off the critical path (the tracker follows the
        # trajectory message), so they may reach the recorder after the next odometry
        data = sorted(data, key=lambda e: (stamp_ns(e.msg.header.stamp), e.kind == 'odom'))
    inputs = TrackerInputs(config, replay_rules(values, mode))
    commands: list[Timed] = []
    for e in data:
        step = _feed(inputs, e)
        if step is not None:
            commands.append((e.receive_ns, _twist_msg(step.command)))
    return ReplayPlan(mode, data, commands, recorded, fed, dict(inputs.ignored), note=note)


class _RefTimeline:
    """Reference states: state ``s`` holds the latest parts after the first ``s`` ref events."""

    def __init__(self, data: list[ReplayEvent]):
        self.events = [e for e in data if e.kind in REF_INDEX]
        self.times = [e.receive_ns for e in self.events]
        self.before: dict[int, int] = {}         # id(odom event) -> state in bag order
        n = 0
        for e in data:
            if e.kind in REF_INDEX:
                n += 1
            else:
                self.before[id(e)] = n

    def parts(self, s: int) -> list[Any]:
        out: list[Any] = [None, None, None]
        i = s - 1
        while i >= 0 and any(p is None for p in out):
            e = self.events[i]
            if out[REF_INDEX[e.kind]] is None:
                out[REF_INDEX[e.kind]] = e.msg
            i -= 1
        return out

    def window(self, t_from: int, t_to: int) -> tuple[int, int]:
        return bisect.bisect_left(self.times, t_from), bisect.bisect_right(self.times, t_to)


def _feed(inputs: TrackerInputs, e: ReplayEvent) -> Step | None:
    """Feed an odometry or reference event; the step it makes due, if any."""
    if e.kind == 'odom':
        return inputs.odom(e.msg)
    return inputs.reference(REF_INDEX[e.kind], e.msg)


def _run(tl: _RefTimeline, odoms: list[ReplayEvent], recorded: list[Timed],
         inputs: TrackerInputs, applied: int, atol: float, limit: int | None = None
         ) -> tuple[TrackerInputs, list[ReplayEvent], list[Timed], int, bool]:
    """Pair odometry j with recorded command j, choosing the reference state that reproduces it.

    Returns (inputs, feed order, commands, swaps, reproduced).
    """
    window = int(ORDER_WINDOW * 1e9)
    order: list[ReplayEvent] = []
    commands: list[Timed] = []
    swaps, matching, k = 0, True, 0
    for od in odoms:
        if limit is not None and k >= limit:
            break
        default = max(tl.before[id(od)], applied)
        chosen: tuple[int, TrackerInputs, Command | None] | None = None
        if matching and k < len(recorded):
            t_o, t_c = od.receive_ns, recorded[k][0]
            # any state from the last one used (the tracker may have taken this odometry
            # before references the recorder got earlier) up to those the recorder got
            # just after the command (the tracker may have had them first)
            hi = tl.window(t_o, max(t_c, t_o) + window)[1]
            # at most 32 of each side (a gap in the odometry with references arriving leaves
            # many states behind: the later ones keep their turn)
            cands = [default] + list(range(default - 1, applied - 1, -1))[:32] \
                + list(range(default + 1, max(hi, default) + 1))[:31]
            # the state that reproduces the command exactly, else the closest within atol:
            # two states may differ by so little (a reference part that barely changed) that
            # both agree within atol, and the wrong one shows tens of commands later, when
            # a clamp no longer hides it
            best = math.inf
            for s in cands:
                trial = inputs.fork()
                for e in tl.events[applied:s]:
                    _feed(trial, e)
                step = trial.odom(od.msg)
                cmd = None if step is None else step.command
                if cmd is None and s == default:
                    chosen = (s, trial, None)        # an input the tracker ignores
                    break
                if cmd is not None:
                    off = _deviation(cmd, recorded[k][1])
                    if off <= atol and off < best:
                        chosen, best = (s, trial, cmd), off
                        if off <= ROUND_OFF * max(1.0, abs(cmd.v), abs(cmd.w)):
                            break
            if chosen is None:
                matching = False
            elif chosen[2] is not None:
                swaps += chosen[0] != default
        if chosen is None:
            trial = inputs.fork()
            for e in tl.events[applied:default]:
                _feed(trial, e)
            step = trial.odom(od.msg)
            chosen = (default, trial, None if step is None else step.command)
        s, inputs, cmd = chosen
        order.extend(tl.events[applied:s])
        applied = s
        order.append(od)
        if cmd is not None:
            commands.append((od.receive_ns, _twist_msg(cmd)))
            k += 1
    return inputs, order, commands, swaps, matching


def _plan_realtime(data: list[ReplayEvent], recorded: list[Timed], config: TrackerConfig,
                   rules: InputRules, atol: float) -> ReplayPlan | None:
    tl = _RefTimeline(data)
    odoms = [e for e in data if e.kind == 'odom']
    t_first = recorded[0][0]
    first = bisect.bisect_right([e.receive_ns for e in odoms], t_first)
    starts = [j for j in range(first - 1, -1, -1)
              if t_first - odoms[j].receive_ns <= START_SEARCH * 1e9][:200]
    # a start is tried first where every command could follow its odometry: a tracker
    # that starts on a queue of odometry answers it in a burst of commands, before the
    # recorder got the next odometry, so the nearest starts cannot be the right one
    receive = [e.receive_ns for e in odoms]
    skew, n = int(START_SKEW * 1e9), min(len(recorded), START_CHECK * 20)

    causal = {j: all(receive[j + c] <= recorded[c][0] + skew
                     for c in range(min(n, len(odoms) - j))) for j in starts}
    starts = [j for j in starts if causal[j]] + [j for j in starts if not causal[j]]
    v_target = float(_twist(recorded[0][1]).linear.x)
    for j in starts:
        od = odoms[j]
        lo, hi = tl.window(od.receive_ns - int(ORDER_WINDOW * 1e9), t_first)
        default = tl.before[id(od)]
        # odometry the tracker had seen before the start: a whole window (it ran for a
        # while; the recorder joined late) or none (its first odometry made its first step;
        # under load a tracker works off a queue of odometry from well before the first
        # recorded command), and at the nearest starts any number in between
        counts = [WINDOW + 1, 0] + (list(range(min(WINDOW, j), 0, -1))
                                    if first - 1 - j < PRIME_SEARCH else [])
        for s, count in ((s, c) for s in [default] + [x for x in range(hi, lo - 1, -1)
                                                     if x != default][:64]
                         for c in counts):
            base = TrackerInputs(config, rules)
            prime = _prime_timing(base, odoms[:j], count)
            base.latest = tl.parts(s)
            if any(p is None for p in base.latest):
                continue
            v0 = _recover_speed(base, od, v_target)
            if v0 is None:
                continue
            start = _with_speed(od, v0)
            tl.before[id(start)] = tl.before[id(od)]
            check = _run(tl, [start] + odoms[j + 1:], recorded, base.fork(), s, atol,
                         limit=START_CHECK)
            if not check[4]:
                continue
            inputs, order, commands, swaps, _ = _run(tl, [start] + odoms[j + 1:], recorded,
                                                     base.fork(), s, atol)
            head: list[ReplayEvent] = []
            seen: set[str] = set()
            for e in reversed(tl.events[:s]):
                if e.kind not in seen:
                    seen.add(e.kind)
                    head.insert(0, e)
                if len(seen) == 3:
                    break
            skipped = sum(1 for e in data if e.receive_ns < od.receive_ns) - len(head)
            return ReplayPlan('realtime', head + order, commands, recorded, {},
                              dict(inputs.ignored), v0, skipped, swaps, prime=tuple(prime))
    return None


def replay(bag: str | os.PathLike[str], *, gains: str | os.PathLike[str] | None = None,
           params: str | os.PathLike[str] | None = None,
           expected: str | os.PathLike[str] | None = None,
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
    max_differences : int, optional
        How many differing commands the result lists.
    namespace : str, optional
        The namespace of the bag's topics.

    Returns
    -------
    ReplayResult
        ``comparison.equal`` tells whether the commands are reproduced; ``plan`` what
        was fed (see :func:`plan_replay`).
    """
    config, values = load_tracker_parameters(gains, params)
    events = read_replay_events(bag, namespace=namespace)
    values = recorded_tuning(events, values)
    plan = plan_replay(events, config, use_recorded=expected is None, atol=max(atol, 1e-9),
                       values=values)
    return finish_replay(bag, plan, plan.commands, expected=expected, atol=atol, rtol=rtol,
                         max_differences=max_differences)


def finish_replay(bag: str | os.PathLike[str], plan: ReplayPlan, commands: list[Timed], *,
                  expected: str | os.PathLike[str] | None = None, atol: float = 1e-9,
                  rtol: float = 0.0, max_differences: int = 20,
                  via: str = 'in process') -> ReplayResult:
    """Compare replayed ``commands`` with the recorded (or ``expected``) ones.

    Parameters
    ----------
    bag : path-like
        The replayed bag (named in the result).
    plan : ReplayPlan
        What was fed (:func:`plan_replay`).
    commands : list of (int, Twist)
        The replayed commands with the receive time of their input (the plan's, or a
        tracker node's over DDS).
    expected : path-like, optional
        Compare with this bag's ``cmd_vel`` instead of the recorded one.
    atol, rtol : float, optional
        Tolerance of the comparison.
    max_differences : int, optional
        How many differing commands the result lists.
    via : str, optional
        How the commands were replayed (the summary says it).

    Returns
    -------
    ReplayResult

    Raises
    ------
    MissingTopicsError
        If there is no ``cmd_vel`` to compare with.
    """
    recorded, source = plan.recorded, 'recorded'
    if expected is not None:
        recorded = [(e.receive_ns, e.msg) for e in read_replay_events(expected)
                    if e.kind == 'cmd']
        source = str(expected)
    if not recorded:
        raise MissingTopicsError(f'{expected or bag} has no {topics.CMD_VEL} to compare the '
                                 'replayed commands with', [topics.CMD_VEL])
    cmp = compare_commands(commands, recorded, atol=atol, rtol=rtol,
                           max_differences=max_differences)
    return ReplayResult(Path(bag), plan.mode, commands, recorded, cmp, plan.fed,
                        plan.ignored, source, via, plan)


def format_replay(res: ReplayResult) -> str:
    """Summary of a replay: inputs fed, commands produced and the comparison.

    Parameters
    ----------
    res : ReplayResult
        What :func:`replay` returned.

    Returns
    -------
    str
    """
    fed = ', '.join(f'{k} {n}' for k, n in sorted(res.inputs.items()))
    lines = [f'replay of {res.bag} ({res.mode}) {res.via}: fed {fed}',
             f'commands: {len(res.commands)} replayed, {len(res.recorded)} '
             f'{"recorded" if res.reference == "recorded" else "in " + res.reference}']
    lines += [f'ignored: {why} ({n})' for why, n in res.ignored.items()]
    plan = res.plan
    if plan is not None and plan.skipped_inputs:
        lines.append(f'started at the tracker\'s first recorded command ({plan.skipped_inputs} '
                     'earlier inputs skipped), compensator speed recovered from it: '
                     f'{plan.initial_speed!r} m/s')
    if plan is not None and plan.adopted_ns is not None:
        lines.append(f'trajectory adopted at the odometry stamped {plan.adopted_ns * 1e-9:.9f} s '
                     f'(as the tracker announced on {topics.FOLLOWED_TRAJECTORY})')
    if plan is not None and plan.swaps:
        lines.append(f'{plan.swaps} odometry message(s) paired with another reference state '
                     'than the bag order gives (the one the recorded command shows)')
    if plan is not None and plan.note:
        lines.append(plan.note)
    if res.comparison.equal:
        lines.append(f'commands reproduced: max |diff| {res.max_abs_error:.3g} '
                     f'({res.comparison.summary[topics.CMD_VEL].align} alignment)')
    else:
        lines.append('commands differ:')
        lines.append(format_differences(res.comparison))
    return '\n'.join(lines)
