"""The main job: run a scenario through the ROS nodes, record a bag, report.

``nonfragile_tracker run`` starts the recorder, tracker, reference and plant as
separate processes (what ``ros2 launch`` does) or composed in this process on
one executor (``--composed``), in deterministic lockstep on simulation time,
shows progress, then writes a report with plots next to the bag.

The ROS environment is kept on this host (ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST)
on a domain id of its own unless the caller set ROS_DOMAIN_ID.

See doc/cli.md, section "run", doc/ros-interface.md, section "Time and lockstep", and
doc/safety.md (domains, stopping).
"""
from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any, Callable

import yaml

from ..interface import topics
from ..errors import InputError
from ..files import node_key, read_yaml


def isolated_env(base: dict[str, Any] | None = None) -> dict[str, Any]:
    """Environment for a run: localhost discovery and this package first on ``PYTHONPATH``.

    The domain id is :func:`reserved_domain`'s, held while a run lasts; this function only
    keeps one the caller set.

    Parameters
    ----------
    base : dict, optional
        The environment to start from (copied); this process's when ``None``.

    Returns
    -------
    dict
        ``base`` with ``ROS_AUTOMATIC_DISCOVERY_RANGE`` and ``PYTHONUNBUFFERED`` set unless
        present, and this package first on ``PYTHONPATH``.
    """
    env = dict(os.environ if base is None else base)
    env.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    env.setdefault('PYTHONUNBUFFERED', '1')
    pkg_root = str(Path(__file__).resolve().parents[2])
    env['PYTHONPATH'] = pkg_root + (os.pathsep + env['PYTHONPATH'] if env.get('PYTHONPATH')
                                     else '')
    return env


@contextlib.contextmanager
def reserved_domain(base: dict[str, Any] | None = None) -> Iterator[dict[str, Any]]:
    """:func:`isolated_env` with a ``ROS_DOMAIN_ID`` of its own while the block lasts.

    Unless ``base`` sets one, the id is reserved with ROS's ``domain_coordinator`` (ids 1 to
    100, in the range ROS calls safe on Linux; a local port held per id, so concurrent runs
    of any process never share one) and freed at the end of the block.

    Parameters
    ----------
    base : dict, optional
        The environment to start from (copied); this process's when ``None``.

    Yields
    ------
    dict
        The environment of the run.
    """
    env = isolated_env(base)
    if env.get('ROS_DOMAIN_ID'):
        yield env
        return
    import domain_coordinator
    with domain_coordinator.domain_id() as domain:
        env['ROS_DOMAIN_ID'] = str(domain)
        yield env


def merge(dst: dict[str, Any], src: dict[str, Any]) -> dict[str, Any]:
    """Merge ``src`` into ``dst`` recursively (nested dicts merged, other values replaced).

    Parameters
    ----------
    dst : dict
        Changed in place.
    src : dict
        Its values win (not copied: ``dst`` may share them).

    Returns
    -------
    dict
        ``dst``.
    """
    for k, v in src.items():
        if isinstance(v, dict) and isinstance(dst.get(k), dict):
            merge(dst[k], v)
        else:
            dst[k] = v
    return dst


def scenario_parameters(scenario: Path, gains: Path | None, overrides: dict[str, Any] | None = None
                        ) -> dict[str, Any]:
    """One parameter mapping {node: {'ros__parameters': {...}}} from the files and overrides.

    File keys may be ``node``, ``/node`` or ``/**/node`` (any namespace); the mapping uses
    the bare node name and :func:`write_parameter_file` writes ``/**/node`` again.

    Parameters
    ----------
    scenario : pathlib.Path
        A ROS 2 parameter file.
    gains : pathlib.Path or None
        A second parameter file merged over the first (the tracker's gains), if any.
    overrides : dict, optional
        ``{node: {'ros__parameters': {...}}}`` merged last.

    Returns
    -------
    dict

    Raises
    ------
    InputError
        If a file cannot be read or is not a ROS 2 parameter file.
    """
    params: dict[str, Any] = {}
    for path in (scenario, gains):
        if path is None:
            continue
        data = read_yaml(path, 'ROS 2 parameter file') or {}
        if not isinstance(data, dict) or not all(
                isinstance(v, dict) and isinstance(v.get('ros__parameters', {}), dict)
                for v in data.values()):
            raise InputError(f'{path}: expected a ROS 2 parameter file '
                             '({node: {ros__parameters: {name: value}}})')
        merge(params, {node_key(str(k)): v for k, v in data.items()})
    merge(params, overrides or {})
    return params


def write_parameter_file(params: dict[str, Any], path: Path) -> Path:
    """ROS 2 parameter file with ``/**/node`` keys, so namespaced nodes match too.

    Parameters
    ----------
    params : dict
        ``{node: {'ros__parameters': {...}}}``; lists mixing ints and floats are written
        as doubles (rcl refuses mixed sequences).
    path : pathlib.Path
        The file to write.

    Returns
    -------
    pathlib.Path
        ``path``.
    """
    path.write_text(yaml.safe_dump({f'/**/{k}': v for k, v in _doubles(params).items()},
                                   sort_keys=False))
    return path


def lockstep_handshake(record: bool) -> dict[str, dict[str, Any]]:
    """Start-up handshake parameters of a lockstep run, per node (``{node: {name: value}}``).

    With a recorder the lockstep publishers wait for two matched subscribers (the
    plant's odom: tracker and recorder; the tracker's cmd_vel: plant and recorder), the
    recorder announces when its own
    subscriptions have matched (``lockstep_gate``) and the plant waits for that
    (``lockstep_recorder``): DDS matching is per side, so both sides are checked and the
    bag gets every step from the first.  The reference's per-step samples are off the
    critical path (the tracker follows the trajectory message): they wait for the recorder
    only, and steps seen before it matched are published then.  Without a recorder the
    plant waits for its one subscriber and the tracker answers at once (a lost first
    sample there is made good by the plant's republished step).

    Parameters
    ----------
    record : bool
        Whether a recorder takes part.

    Returns
    -------
    dict
        ``lockstep_subscribers`` of the plant, tracker and reference, the plant's
        ``lockstep_recorder`` and, with a recorder, its ``lockstep_gate``.
    """
    n = 2 if record else 0
    out = {'plant': {'lockstep_subscribers': max(n, 1), 'lockstep_recorder': record},
           'tracker': {'lockstep_subscribers': n},
           'reference': {'lockstep_subscribers': 1 if record else 0}}
    if record:
        out['recorder'] = {'lockstep_gate': True}
    return out


def realtime_handshake(record: bool) -> dict[str, dict[str, Any]]:
    """Start-up handshake parameters of a real-time run, per node (``{node: {name: value}}``).

    With a recorder, the plant starts stepping (the run's clock) only once the recorder
    has announced on ``recorder/ready`` that its odom and cmd_vel subscriptions have
    matched and odom has two matched subscribers (DDS discovery can take seconds under
    load, and matches each side on its own), and the tracker adopts a trajectory only
    once cmd_vel has two (plant, recorder): the bag has every odometry message and
    every command from the first (what a replay needs).

    Parameters
    ----------
    record : bool
        Whether a recorder takes part; without one nothing waits.

    Returns
    -------
    dict
        Empty without a recorder; else the plant's ``realtime_recorder``
        and the plant's and tracker's ``lockstep_subscribers``, the recorder's
        ``lockstep_gate``.
    """
    if not record:
        return {}
    return {'plant': {'realtime_recorder': True, 'lockstep_subscribers': 2},
            'tracker': {'lockstep_subscribers': 2}, 'recorder': {'lockstep_gate': True}}


def with_horizon(params: dict[str, Any]) -> dict[str, Any]:
    """``params`` with the reference's ``horizon`` fitted to the plant's ``duration``.

    A built-in path is published as a trajectory over ``[0, horizon]``; after it the
    tracker brings the robot to rest.  A lockstep run ends after ``duration``: the
    horizon is ``duration`` + 1 s unless the parameters give one (then at least that);
    a real-time plant with ``duration`` 0 runs until stopped: the default horizon stays.

    Parameters
    ----------
    params : dict
        ``{node: {'ros__parameters': {...}}}``, changed in place.

    Returns
    -------
    dict
        ``params``.
    """
    plant = params.get('plant', {}).get('ros__parameters', {})
    ref = params.setdefault('reference', {}).setdefault('ros__parameters', {})
    duration = float(plant.get('duration', 60.0))
    if duration <= 0.0:
        return params
    if 'horizon' not in ref or duration + 1.0 > float(ref['horizon']):
        ref['horizon'] = duration + 1.0
    return params


def lockstep_parameters(record: bool, samples: bool = True) -> dict[str, dict[str, Any]]:
    """Per-node parameters of a lockstep run: :func:`lockstep_handshake` and the message set.

    The tracker follows only the trajectory message (``wait_for_trajectory``: the
    reference publishes the built-in path as one in lockstep), so a step is ``odom`` in,
    ``cmd_vel`` out; the reference publishes its per-step samples only for a recorder that
    records them (``publish_samples`` = ``record and samples``; without them it has no
    ``/clock`` subscription either).  Real-time runs keep the defaults (the tracker follows
    the samples of a built-in path there).

    Parameters
    ----------
    record : bool
        Whether a recorder takes part.
    samples : bool, optional
        Whether it records the reference's per-step samples.

    Returns
    -------
    dict
    """
    out = lockstep_handshake(record)
    out['tracker']['wait_for_trajectory'] = True
    out['reference']['publish_samples'] = record and samples
    return out


#: The reference's per-step sample topics (published in lockstep only when recorded).
_SAMPLE_TOPICS = (topics.REF_POSE, topics.REF_TWIST, topics.REF_ACCEL)


def recorded_topics(params: dict[str, Any], recorder_topics: Sequence[str] | None = None,
                    record_all: bool = False) -> list[str]:
    """The topics a recorded run records.

    ``recorder_topics`` if given, else the recorder's ``topics`` parameter of ``params``,
    else every topic (:data:`.topics.TYPES`) with ``record_all`` or in real time (the
    samples are what a real-time tracker follows), else the lean lockstep set
    :data:`.topics.LEAN_TOPICS` (per step only ``odom`` and ``cmd_vel``; the reference is
    reconstructed from the recorded trajectory message by the bag reader).

    Parameters
    ----------
    params : dict
        The run's node parameters.
    recorder_topics : sequence of str, optional
        Topics named by the caller.
    record_all : bool, optional
        Record every topic.

    Returns
    -------
    list of str
    """
    if recorder_topics:
        return list(recorder_topics)
    configured = params.get('recorder', {}).get('ros__parameters', {}).get('topics')
    if configured:
        return [str(t) for t in configured]
    if record_all or _is_realtime(params):
        return list(topics.TYPES)
    return list(topics.LEAN_TOPICS)


def records_samples(names: Sequence[str]) -> bool:
    """True if ``names`` (recorder topics) include a per-step reference sample topic.

    Parameters
    ----------
    names : sequence of str
        Topic names, with or without a leading ``/``.

    Returns
    -------
    bool
    """
    return any(str(n).lstrip('/') in _SAMPLE_TOPICS for n in names)


def _ros_args(values: dict[str, Any]) -> list[str]:
    """``-p name:=value`` arguments (booleans and integers only)."""
    out: list[str] = []
    for k, v in values.items():
        out += ['-p', f'{k}:={str(v).lower() if isinstance(v, bool) else v}']
    return out


@dataclass
class RunResult:
    """Outcome of a run: its directory, bag (if recorded), exit code per node, wall time, steps."""

    run_dir: Path | None        # None: a run without a directory (nothing recorded)
    bag: Path | None
    exit_codes: Mapping[str, int | None]
    wall_time: float
    steps: int


def _doubles(value: Any) -> Any:
    """Lists mixing ints and floats are written as doubles (rcl rejects mixed sequences)."""
    if isinstance(value, dict):
        return {k: _doubles(v) for k, v in value.items()}
    if isinstance(value, list) and any(isinstance(v, float) for v in value):
        return [float(v) if isinstance(v, int) and not isinstance(v, bool) else v for v in value]
    return value


#: Real time: how long the recorder keeps recording after the plant has finished (s).
_REALTIME_TAIL_S = 0.3
#: Real time: longest wait for the recorder to start before the plant is started (s).
_REALTIME_START_WAIT_S = 30.0
#: How long a node may take to exit after the runner's SIGINT before it is killed (s).
STOP_WAIT_S = 10.0


class NodeProcess:
    """One node in a process of its own (``nodes.entry``), its output in a log file.

    The one lifecycle of the runner's nodes, the replayer's tracker and the bring-up
    command's nodes: started with a parameter file; :meth:`interrupt` (SIGINT, as Ctrl-C),
    :meth:`wait`, and :meth:`stop`, which interrupts, waits and - for a node that does not
    end - writes its stacks to its log (or the terminal) before killing it
    (:func:`kill_with_stacks`).

    Parameters
    ----------
    name : str
        The node (``tracker``, ``plant``, ...), run by ``python -m nonfragile_tracker.nodes.entry``.
    params_file : pathlib.Path
        Its ROS 2 parameter file.
    log : pathlib.Path or None
        Its output (stdout and stderr), written from the start (None: this process's
        terminal).
    env : mapping or None
        Its environment (:func:`reserved_domain`; None: this process's).
    extra : sequence of str, optional
        More ``--ros-args`` (``-p name:=value``, ``-r from:=to``).
    """

    def __init__(self, name: str, params_file: Path, log: Path | None,
                 env: Mapping[str, str] | None, extra: Sequence[str] = ()) -> None:
        self.name, self.log = name, log
        self._out = open(log, 'w') if log is not None else None
        self.proc = subprocess.Popen(
            [sys.executable, '-m', 'nonfragile_tracker.nodes.entry', name, '--ros-args',
             '--params-file', str(params_file), *extra],
            env=env, stdout=self._out, stderr=subprocess.STDOUT if log is not None else None,
            text=True)

    def poll(self) -> int | None:
        """Its exit code, None while it runs."""
        return self.proc.poll()

    def interrupt(self, signum: int = signal.SIGINT) -> None:
        """SIGINT (a node's clean shutdown; or ``signum``), if it still runs.

        Parameters
        ----------
        signum : int, optional
            The signal (SIGTERM ends a node cleanly too).
        """
        if self.proc.poll() is None:
            self.proc.send_signal(signum)

    def wait(self, timeout: float) -> bool:
        """Whether it ended within ``timeout`` s.

        Parameters
        ----------
        timeout : float
            Seconds to wait.
        """
        try:
            self.proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            return False
        return True

    def stop(self, timeout: float | None = None) -> bool:
        """SIGINT, then wait; a node still running is killed after dumping its stacks.

        Parameters
        ----------
        timeout : float, optional
            Seconds to wait after SIGINT (default :data:`STOP_WAIT_S`).

        Returns
        -------
        bool
            True if it ended on its own, False if it was killed.
        """
        self.interrupt()
        if self.wait(STOP_WAIT_S if timeout is None else timeout):
            return True
        kill_with_stacks(self.proc)
        return False

    def close(self) -> None:
        """Close this side of its log file (after it has ended)."""
        if self._out is not None:
            self._out.close()


def _wait_for_line(log: Path, text: str, proc: NodeProcess, timeout: float) -> bool:
    """Wait until ``log`` contains ``text`` (True), ``proc`` exits or ``timeout`` s pass."""
    end = time.monotonic() + timeout
    while time.monotonic() < end and proc.poll() is None:
        try:
            if text in log.read_text(errors='replace'):
                return True
        except OSError:
            pass
        time.sleep(0.05)
    return False


def _is_realtime(params: dict[str, Any]) -> bool:
    """True if the plant of ``params`` runs in ``mode: realtime``.

    Parameters
    ----------
    params : dict
        The run's node parameters.

    Returns
    -------
    bool
    """
    return bool(params.get('plant', {}).get('ros__parameters', {}).get('mode') == 'realtime')


def realtime_overrides() -> dict[str, Any]:
    """Overrides that put plant, reference and tracker in real-time mode (wall timers).

    The plant steps on a wall timer for its ``duration`` (0: forever), the reference
    publishes at ``publish_rate`` and the tracker answers each odometry message; for
    :func:`scenario_parameters` and :func:`run_processes`.
    """
    return {n: {'ros__parameters': {'mode': 'realtime'}} for n in ('plant', 'reference',
                                                                   'tracker')}


def run_processes(params: dict[str, Any], run_dir: Path, *, record: bool = True,
                  env: dict[str, Any] | None = None,
                  timeout: float = 600.0, progress: Callable[[str], object] = print,
                  recorder_topics: list[str] | None = None,
                  record_all: bool = False) -> RunResult:
    """Run the scenario with one process per node; returns exit codes per node.

    Each node's output goes to ``<run_dir>/<node>.log``; the plant's progress lines
    are passed to ``progress``.  If a node dies before the plant has finished, the
    run is stopped at once (its exit code tells which).  With the plant in
    ``mode: realtime`` (see :func:`realtime_overrides`) the recorder records on the
    wall clock (no sim time, no start gate) and is stopped once the plant has run its
    ``duration``.  The recorder records :func:`recorded_topics` (``recorder_topics``,
    ``record_all``): in lockstep by default the lean set.

    Parameters
    ----------
    params : dict
        ``{node: {'ros__parameters': {...}}}`` (:func:`scenario_parameters`).
    run_dir : pathlib.Path
        Existing folder of the run: parameter file, logs and the bag (``bag``).
    record : bool, optional
        Start the recorder.
    env : dict, optional
        Base environment of the nodes (:func:`reserved_domain`).
    timeout : float, optional
        Wall time [s] after which the run is stopped.
    progress : callable, optional
        Called with each progress line.
    recorder_topics : list of str, optional
        The topics to record (default :func:`recorded_topics`).
    record_all : bool, optional
        Record every topic.

    Returns
    -------
    RunResult
    """
    with reserved_domain(env) as env:
        params_file = write_parameter_file(with_horizon(params), run_dir / 'params.yaml')
        procs: dict[str, NodeProcess] = {}
        bag = run_dir / 'bag' if record else None
        t0 = time.monotonic()

        def start(name: str, extra: Sequence[str] = ()) -> None:
            procs[name] = NodeProcess(name, params_file, run_dir / f'{name}.log', env, extra)

        realtime = _is_realtime(params)
        names = recorded_topics(params, recorder_topics, record_all)
        hand = realtime_handshake(record) if realtime else \
            lockstep_parameters(record, records_samples(names))
        try:
            if record:
                extra = ['-p', f'output:={bag}'] + _ros_args(hand['recorder']) + (
                    [] if realtime else ['-p', 'use_sim_time:=true'])
                extra += ['-p', 'topics:=[' + ','.join(f"'{t}'" for t in names) + ']']
                start('recorder', extra)
            start('tracker', _ros_args(hand.get('tracker', {})))
            if realtime and record:
                # the real-time plant steps and the reference's time runs from their start:
                # let the recorder subscribe first, then start both together
                _wait_for_line(run_dir / 'recorder.log', 'recording', procs['recorder'],
                               _REALTIME_START_WAIT_S)
            start('reference', _ros_args(hand.get('reference', {})))
            start('plant', _ros_args(hand.get('plant', {})))
            _watch_plant(procs, run_dir, t0 + timeout, progress)
            plant = procs['plant']
            if plant.poll() is not None and record and realtime:
                time.sleep(_REALTIME_TAIL_S)          # the last messages in flight, then stop
                procs['recorder'].interrupt()
                if not procs['recorder'].wait(30):
                    progress('[runner] the recorder did not stop within 30 s of SIGINT; '
                             'killing it')          # the finally below kills it
            elif plant.poll() is not None and record and not procs['recorder'].wait(30):
                procs['recorder'].interrupt()
                procs['recorder'].wait(30)
        finally:
            for p in procs.values():
                p.interrupt()
            for name, p in procs.items():
                if not p.stop():
                    progress(f'[runner] {name} did not exit within {STOP_WAIT_S:g} s of SIGINT; '
                             f'killed it (its stacks are in {p.log})')
                p.close()
        codes = {name: p.poll() for name, p in procs.items()}
        steps = int(round(params['plant']['ros__parameters'].get('duration', 60.0)
                          / params['plant']['ros__parameters'].get('dt', 0.01)))
        return RunResult(run_dir, bag, codes, time.monotonic() - t0, steps)


def _report_plant(reader: IO[str], progress: Callable[[str], object]) -> None:
    """Pass the plant log's new progress, error and completion lines to ``progress``."""
    for line in reader.readlines():
        line = line.rstrip()
        if 'progress:' in line or 'ERROR' in line or 'FATAL' in line or 'complete' in line:
            progress(f'[plant] {line.split("] ", 1)[-1] if "] " in line else line}')


def _watch_plant(procs: dict[str, NodeProcess], run_dir: Path, deadline: float,
                 progress: Callable[[str], object]) -> None:
    """Until the plant ends, another node dies or the (monotonic) deadline: its progress."""
    plant = procs['plant']
    with open(run_dir / 'plant.log') as reader:
        while plant.poll() is None:
            _report_plant(reader, progress)
            # the recorder closes its bag and exits 0 right after run_done, which can be
            # before the plant's last poll here: that is the end of the run, not a death
            dead = {n: p.poll() for n, p in procs.items()
                    if n != 'plant' and p.poll() is not None
                    and not (n == 'recorder' and p.poll() == 0)}
            if dead:
                progress(f'[runner] node(s) exited early: {dead}; stopping the run '
                         f'(logs in {run_dir})')
                break
            if time.monotonic() > deadline:
                progress('[runner] timeout: stopping the run')
                break
            time.sleep(0.05)
        _report_plant(reader, progress)


def kill_with_stacks(proc: subprocess.Popen[Any], grace: float = 0.5) -> None:
    """Kill a node process that did not end, after asking it for its stacks (SIGUSR1).

    A node process writes every thread's Python stack to its output (its log) on SIGUSR1
    (:func:`nonfragile_tracker.nodes.entry.dump_stacks_on_sigusr1`) and goes on; ``grace``
    s later it is killed.  Nothing happens to a process that has ended.

    Parameters
    ----------
    proc : subprocess.Popen
        The node process.
    grace : float, optional
        Seconds between SIGUSR1 and the kill.
    """
    if proc.poll() is None:
        proc.send_signal(signal.SIGUSR1)
        try:
            proc.wait(grace)
        except subprocess.TimeoutExpired:
            pass
    if proc.poll() is None:
        proc.kill()
        proc.wait()


def log_tail(run_dir: Path, name: str, lines: int = 25) -> str:
    """The last ``lines`` lines of node ``name``'s log in ``run_dir`` ('' if it has none).

    Parameters
    ----------
    run_dir : pathlib.Path
        The run's folder.
    name : str
        The node (its log is ``<name>.log``).
    lines : int, optional
        How many lines.

    Returns
    -------
    str
    """
    try:
        text = (run_dir / f'{name}.log').read_text(errors='replace')
    except OSError:
        return ''
    return '\n'.join(text.splitlines()[-lines:])


def run_composed(params: dict[str, Any], run_dir: Path | None, *, record: bool = True,
                 timeout: float = 600.0, recorder_topics: list[str] | None = None,
                 record_all: bool = False) -> RunResult:
    """Run the scenario with all nodes in this process on one executor.

    The recorder records :func:`recorded_topics` (in lockstep by default the lean set).

    Parameters
    ----------
    params : dict
        ``{node: {'ros__parameters': {...}}}`` (:func:`scenario_parameters`).
    run_dir : pathlib.Path or None
        Folder of the bag (``bag``); required with ``record``.
    record : bool, optional
        Add the recorder node.
    timeout : float, optional
        Wall time [s] after which the run is stopped.
    recorder_topics : list of str, optional
        The topics to record (default :func:`recorded_topics`).
    record_all : bool, optional
        Record every topic.

    Returns
    -------
    RunResult

    Raises
    ------
    InputError
        If ``record`` is set without a ``run_dir``.
    """
    params = with_horizon(params)
    t0 = time.monotonic()
    # a private context on a domain of our own (localhost discovery): no cross-talk
    with reserved_domain() as env:
        return _spin_composed(params, run_dir, env, record=record, timeout=timeout,
                              names=recorded_topics(params, recorder_topics, record_all), t0=t0)


def _spin_composed(params: dict[str, Any], run_dir: Path | None, env: dict[str, Any], *,
                   record: bool, timeout: float, names: list[str], t0: float) -> RunResult:
    """:func:`run_composed` in the environment ``env`` (its domain, its discovery range)."""
    import rclpy

    from ..nodes.common import AdapterNode, make_executor, overrides
    from ..nodes.plant import PlantNode
    from ..nodes.reference import ReferenceNode
    from ..nodes.tracker import TrackerNode

    def node_overrides(name: str, extra: dict[str, Any] | None = None) -> list[Any]:
        vals = dict(params.get(name, {}).get('ros__parameters', {}))
        vals.update(extra or {})
        return overrides(**vals)

    ctx = rclpy.Context()
    # rcl reads the discovery range from the environment at init: set it for the init
    # only, so that this process's environment is as the caller left it
    key = 'ROS_AUTOMATIC_DISCOVERY_RANGE'
    before = os.environ.get(key)
    os.environ[key] = env[key]
    try:
        rclpy.init(context=ctx, domain_id=int(env['ROS_DOMAIN_ID']))
    finally:
        if before is None:
            del os.environ[key]
        else:
            os.environ[key] = before
    nodes: list[AdapterNode[Any]] = []
    bag = None
    # real time in one process: no start gate (the nodes share one executor)
    hand = {} if _is_realtime(params) else lockstep_parameters(record, records_samples(names))
    try:
        if record:
            from ..nodes.recorder import Recorder
            if run_dir is None:
                raise InputError('a recorded run needs a run directory (got None)')
            bag = run_dir / 'bag'
            rec_params = {'output': str(bag), 'use_sim_time': True, **hand.get('recorder', {})}
            rec_params.update(params.get('recorder', {}).get('ros__parameters', {}))
            rec_params['topics'] = names
            nodes.append(Recorder(context=ctx, parameter_overrides=overrides(**rec_params)))
        nodes.append(TrackerNode(parameter_overrides=node_overrides(
            'tracker', hand.get('tracker')), context=ctx))
        nodes.append(ReferenceNode(parameter_overrides=node_overrides(
            'reference', hand.get('reference')), context=ctx))
        plant = PlantNode(context=ctx, parameter_overrides=node_overrides('plant',
                                                                          hand.get('plant')))
        nodes.append(plant)
        ex = make_executor(ctx)
        for n in nodes:
            ex.add_node(n)
        rec = nodes[0] if record else None
        deadline = time.monotonic() + timeout
        while ctx.ok() and time.monotonic() < deadline:
            ex.spin_once(timeout_sec=0.05)
            if plant.finished and (rec is None or rec.finished):
                break
        codes = {'plant': plant.exit_code}
        if rec is not None:
            codes['recorder'] = getattr(rec, 'exit_code', 0)
        return RunResult(run_dir, bag, codes, time.monotonic() - t0, plant.final_step)
    finally:
        for n in nodes:
            close = getattr(n, 'close', None)
            if close is not None:
                close()
            n.destroy_node()
        rclpy.try_shutdown(context=ctx)
