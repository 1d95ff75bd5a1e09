"""Clean shutdown under the signal patterns of a terminal, ``ros2 launch``, systemd and a
test harness: every node exits 0, no traceback anywhere, the bag is complete.

The nodes are started as ``ros2 launch`` starts them: one process each, all in one process
group (of their own, so pytest is not signalled).  Patterns:

- ``launch``: Ctrl-C in a terminal running ``ros2 launch`` - the terminal sends SIGINT to
  the whole foreground group, then launch forwards SIGINT to each node shortly after;
- ``sigint``: one SIGINT to each node (a harness, ``kill -INT``);
- ``sigterm``: SIGTERM to the group (systemd's ``KillMode=control-group``, ``docker stop``).

The real ``ros2 launch`` is not installable here; this reproduces its signal pattern.
"""
from __future__ import annotations

import contextlib
import os
import queue
import random
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

from conftest import CONFIG, ROOT, domain_ids, kill_with_stacks, unique_domain_id
from nonfragile_tracker.bag.reader import mcap_is_complete, read_bag
from nonfragile_tracker.workflows.runner import lockstep_handshake, scenario_parameters, write_parameter_file

NODES = ('recorder', 'tracker', 'reference', 'plant')
#: (pattern, mode, trials): 20 trials in all
#: The soak run (``make soak``) repeats the trials to catch rare races: 20 in all.
SOAK = os.environ.get('NONFRAGILE_SOAK') == '1'
#: (pattern, mode, trials): every signal pattern in both modes; the suite runs 8 trials
#: (two rounds of four), the soak run 20.
PLAN = [('launch', 'lockstep', 4 if SOAK else 2), ('launch', 'realtime', 4 if SOAK else 2),
        ('sigint', 'lockstep', 3 if SOAK else 1), ('sigint', 'realtime', 3 if SOAK else 1),
        ('sigterm', 'lockstep', 3 if SOAK else 1), ('sigterm', 'realtime', 3 if SOAK else 1)]
BAD = ('Traceback', '[FATAL]', 'Error occurred at', 'failed to shutdown', 'context is invalid')
#: rcl's own line when a signal lands inside a log call: rclpy's signal thread invalidates
#: the context between rcl printing a message and publishing it on /rosout.  Nodes check
#: for a stop before logging (AdapterNode.log), which leaves only that call itself open
#: (seen in 2 of about 10 runs of the start-up test, 16 signals each, once with that
#: check).  It is not a traceback and changes nothing else (exit 0, bag closed), so it is
#: the one line not counted.
ROSOUT_RACE = "Failed to publish log message to rosout: publisher's context is invalid"


def _bad(text: str) -> list[str]:
    """The words of :data:`BAD` in a node's output, rcl's /rosout race line left out."""
    text = '\n'.join(line for line in text.splitlines() if not line.startswith(ROSOUT_RACE))
    return [w for w in BAD if w in text]


class DomainPool:
    """``n`` ROS domains for trials run ``n`` at a time: a trial holds one that no running
    trial has.  (A thread pool hands the next job to whichever thread is free: domain
    ``k % n`` could still be in use by job ``k - n``, whose plant the new trial's tracker
    would hear - it did, a lockstep run stalled on the other run's odometry stamps.)"""

    def __init__(self, name: str, n: int):
        self._free: queue.SimpleQueue[int] = queue.SimpleQueue()
        for d in domain_ids(name, n):
            self._free.put(d)

    @contextlib.contextmanager
    def env(self, base: dict) -> Iterator[dict]:
        domain = self._free.get()
        try:
            yield dict(base, ROS_DOMAIN_ID=str(domain))
        finally:
            self._free.put(domain)


class Launch:
    """The four nodes as processes in one process group, logs in ``<dir>/<node>.log``."""

    def __init__(self, run_dir: Path, mode: str, env: dict,
                 scenario: str = 'paper_scenario.yaml'):
        self.dir = run_dir
        self.bag = run_dir / 'bag'
        hand = lockstep_handshake(record=True)
        ov = {node: {'ros__parameters': {'mode': mode, **hand[node]}}
              for node in ('plant', 'tracker', 'reference')}
        ov['plant']['ros__parameters']['duration'] = 600.0
        params = write_parameter_file(scenario_parameters(
            CONFIG / scenario, CONFIG / 'tracker_gains.yaml', ov),
            run_dir / 'params.yaml')
        self.t_start = time.monotonic()
        extra = {'recorder': ['-p', f'output:={self.bag}', '-p', 'flush_period:=0.2']
                 + (['-p', 'use_sim_time:=true', '-p', 'lockstep_gate:=true']
                    if mode == 'lockstep' else [])}
        self.procs: dict[str, subprocess.Popen] = {}
        self.pgid = 0
        for name in NODES:
            cmd = [sys.executable, '-m', 'nonfragile_tracker.nodes.entry', name, '--ros-args',
                   '--params-file', str(params), *extra.get(name, [])]
            with open(run_dir / f'{name}.log', 'w') as log:
                p = subprocess.Popen(cmd, env=env, stdout=log, stderr=subprocess.STDOUT,
                                     stdin=subprocess.DEVNULL, process_group=self.pgid)
            self.procs[name] = p
            self.pgid = self.pgid or p.pid         # the first node leads the group

    def log(self, name: str) -> str:
        return (self.dir / f'{name}.log').read_text()

    def wait_ready(self, timeout: float = 60.0) -> None:
        """Until the loop is closed and recorded: the recorder got the first message on
        odom, the command and the three reference topics (a tracking bag needs all five)."""
        deadline = time.monotonic() + timeout
        while not all(f'first message on /{t}' in self.log('recorder')
                      for t in ('odom', 'cmd_vel', 'reference/pose', 'reference/twist',
                                'reference/accel')):
            dead = {n: p.returncode for n, p in self.procs.items() if p.poll() is not None}
            assert not dead, (dead, {n: self.log(n)[-1500:] for n in dead})
            assert time.monotonic() < deadline, {n: self.log(n)[-800:] for n in NODES}
            time.sleep(0.05)

    def signal(self, pattern: str, rng: random.Random) -> None:
        if pattern == 'launch':
            os.killpg(self.pgid, signal.SIGINT)            # the terminal: the whole group
            time.sleep(rng.uniform(0.0, 0.05))
            for p in self.procs.values():                  # launch forwards it to each node
                if p.poll() is None:
                    p.send_signal(signal.SIGINT)
        elif pattern == 'sigint':
            for p in rng.sample(list(self.procs.values()), len(self.procs)):
                p.send_signal(signal.SIGINT)
                time.sleep(rng.uniform(0.0, 0.02))
        else:
            os.killpg(self.pgid, signal.SIGTERM)

    def wait(self, timeout: float = 30.0) -> tuple[dict, dict]:
        """Exit codes (``'hung'`` after ``timeout``) and exit times (s) per node."""
        t0 = time.monotonic()
        codes, times = {}, {}
        while len(codes) < len(self.procs) and time.monotonic() - t0 < timeout:
            for name, p in self.procs.items():
                if name not in codes and p.poll() is not None:
                    codes[name], times[name] = p.returncode, time.monotonic() - t0
            time.sleep(0.01)
        for name in self.procs:
            codes.setdefault(name, 'hung')
        return codes, times

    def kill(self) -> None:
        for p in self.procs.values():
            kill_with_stacks(p)                 # a hung node's log shows where


def _trial(tmp_path: Path, env: dict, pattern: str, mode: str, i: int, seed: int) -> dict:
    """One trial: start, wait until the loop is closed, signal, collect codes/logs/bag."""
    rng = random.Random(seed)
    trial = f'{pattern}/{mode}/{i}'
    run_dir = tmp_path / trial.replace('/', '_')
    run_dir.mkdir()
    t_start = time.monotonic()
    launch = Launch(run_dir, mode, env)
    try:
        launch.wait_ready()
        time.sleep(rng.uniform(0.0, 0.3))                # somewhere in the run
        t0 = time.monotonic()
        launch.signal(pattern, rng)
        codes, exit_times = launch.wait()
    finally:
        launch.kill()
    print(f'{trial}: ready after {t0 - t_start:.1f} s, exited after ' + ', '.join(
        f'{n} {t:.2f}' for n, t in exit_times.items()) + ' s', file=sys.stderr)
    logs = {n: launch.log(n) for n in NODES}
    return {'trial': trial, 'codes': codes, 'logs': logs, 'bag': launch.bag}


@pytest.mark.ros
@pytest.mark.slow
def test_signal_patterns_end_every_node_cleanly(tmp_path, ros_env):
    """8 trials (20 in the soak run), four at a time, each on a domain of its own."""
    jobs = [(pattern, mode, i) for pattern, mode, n in PLAN for i in range(n)]
    assert len(jobs) == (20 if SOAK else 8)

    domains = DomainPool('signal-patterns', 4)                      # four at a time

    def job(k: int):
        with domains.env(ros_env) as env:
            return _trial(tmp_path, env, *jobs[k], seed=1000 + k)

    with ThreadPoolExecutor(max_workers=4) as pool:
        results = list(pool.map(job, range(len(jobs))))
    failures = []
    for r in results:
        bad = {n: _bad(text) for n, text in r['logs'].items()}
        bad = {n: w for n, w in bad.items() if w}
        if any(c != 0 for c in r['codes'].values()) or bad:
            failures.append((r['trial'], r['codes'], bad,
                             {n: r['logs'][n][-1500:] for n in bad or NODES}))
    assert not failures, failures
    for r in results:
        # the recorder closed a complete, readable bag on every signal path
        bag, rec_log = r['bag'], r['logs']['recorder']
        assert (bag / 'metadata.yaml').exists(), (r['trial'], rec_log)
        assert mcap_is_complete(next(bag.glob('*.mcap'))), r['trial']
        data = read_bag(bag, strict=False)
        assert data.counts.get('/cmd_vel', 0) > 0 and data.counts.get('/odom', 0) > 0, \
            (r['trial'], data.counts, rec_log)
        assert 'bag closed' in rec_log, r['trial']
    # no node hung: each exited within Launch.wait's 30 s (a code, not 'hung', checked above);
    # on a quiet machine they are gone within about 2 s, under heavy load it can take 15 s


#: ``ros2 launch`` sends SIGTERM to a node still alive this long after its SIGINT (and
#: reports "failed to terminate '5' seconds after receiving 'SIGINT'"), SIGKILL as long after.
LAUNCH_SIGTERM_TIMEOUT = 5.0
#: Issue 30, item 4: every node ends within this long (s) of Ctrl-C, at any moment.
STOP_TARGET = 1.0
#: Ctrl-C moments (s after the launch) of the suite's trials: interpreter and imports,
#: rclpy init and the reference building an hour of knots, the loop closing, the run.
STOP_MOMENTS = (0.2, 0.8, 1.6, 4.0)


def launch_stop_trial(run_dir: Path, env: dict, moment: float, seed: int) -> dict:
    """Ctrl-C under ``ros2 launch``, ``moment`` s after it started the nodes.

    The nodes of ``tracking.launch.py record:=true`` (lockstep, the figure eight of
    ``config/latency_scenario.yaml``, a 600 s run and the reference's default horizon of
    an hour: 48,001 knots) as launch starts them, each its console entry's process; the
    terminal's SIGINT to the group, launch's own SIGINT to each node right after, and
    launch's escalation: SIGTERM to a node alive :data:`LAUNCH_SIGTERM_TIMEOUT` s after,
    SIGKILL as long again after that.  A node still alive near :data:`STOP_TARGET` gets
    SIGUSR1 (its stacks into its log, which a failure shows).  The signal waits until every node's entry module
    has its handlers (:func:`_catches_sigterm`; before them, tens of ms of the
    interpreter's own start-up, Python's default SIGINT action applies).

    Returns
    -------
    dict
        ``exit`` (s from the terminal's SIGINT to each node's end), ``codes``,
        ``escalated`` (nodes launch would have sent SIGTERM), ``logs``, ``moment`` (the
        actual one, s after the launch).
    """
    rng = random.Random(seed)
    launch = Launch(run_dir, 'lockstep', env, scenario='latency_scenario.yaml')
    exits: dict[str, float] = {}
    escalated: list[str] = []
    dumped: list[str] = []
    try:
        while time.monotonic() < launch.t_start + moment or not all(
                p.poll() is not None or _catches_sigterm(p.pid) for p in launch.procs.values()):
            time.sleep(0.001)
        t0 = time.monotonic()
        launch.signal('launch', rng)
        while len(exits) < len(launch.procs):
            now = time.monotonic() - t0
            for name, p in launch.procs.items():
                if name not in exits and p.poll() is not None:
                    exits[name] = now
                elif name not in exits and name not in dumped and now > 0.8 * STOP_TARGET:
                    dumped.append(name)                # where it is: stacks in its log
                    p.send_signal(signal.SIGUSR1)
                elif name not in exits and name not in escalated and \
                        now > LAUNCH_SIGTERM_TIMEOUT:
                    escalated.append(name)             # launch: 'escalating to SIGTERM'
                    p.send_signal(signal.SIGTERM)
            if now > 2 * LAUNCH_SIGTERM_TIMEOUT:
                break                                  # launch: SIGKILL (below)
            time.sleep(0.002)
    finally:
        launch.kill()
    return {'exit': exits, 'codes': {n: p.returncode for n, p in launch.procs.items()},
            'escalated': escalated, 'logs': {n: launch.log(n) for n in NODES},
            'moment': t0 - launch.t_start}


def _launch_stop_failures(results: list[dict], limit: float) -> list:
    """Trials where a node did not end cleanly (code 0, no traceback) within ``limit`` s."""
    bad = []
    for r in results:
        slow = {n: round(t, 2) for n, t in r['exit'].items() if t > limit}
        words = {n: w for n, w in ((n, _bad(text)) for n, text in r['logs'].items()) if w}
        if slow or r['escalated'] or words or any(c != 0 for c in r['codes'].values()):
            bad.append((round(r['moment'], 2), slow, r['escalated'], r['codes'], words,
                        {n: r['logs'][n][-3000:] for n in (words or slow or NODES)}))
    return bad


@pytest.mark.ros
def test_ctrl_c_under_launch_ends_every_node_at_once(tmp_path, ros_env):
    """Ctrl-C under ``ros2 launch`` at chosen moments of start-up and run (the soak run:
    20 random moments in the first 8 s): every node ends with 0, no traceback, none
    escalated to SIGTERM (issue 30 had 8 of 8).  The soak run also holds the issue's target,
    every node within :data:`STOP_TARGET` s (benchmarks/ measures the times on a quiet
    machine; a loaded one stretches every process)."""
    rng = random.Random(30)
    moments = [rng.uniform(0.0, 8.0) for _ in range(20)] if SOAK else list(STOP_MOMENTS)
    domains = DomainPool('launch-stop', 2)                          # two at a time

    def trial(k: int) -> dict:
        run_dir = tmp_path / f'stop_{k}'
        run_dir.mkdir()
        with domains.env(ros_env) as env:
            return launch_stop_trial(run_dir, env, moments[k], seed=3000 + k)

    with ThreadPoolExecutor(max_workers=2) as pool:
        results = list(pool.map(trial, range(len(moments))))
    for r in results:
        print(f'Ctrl-C {r["moment"]:.2f} s after launch: ' + ', '.join(
            f'{n} {t:.2f}' for n, t in sorted(r['exit'].items())) + ' s', file=sys.stderr)
    failures = _launch_stop_failures(results, STOP_TARGET if SOAK else LAUNCH_SIGTERM_TIMEOUT)
    for moment, slow, escalated, codes, words, logs in failures:      # the whole story
        print(f'FAILED: Ctrl-C {moment} s after launch: slow {slow}, escalated {escalated}, '
              f'codes {codes}, {words}', file=sys.stderr)
        for name, text in logs.items():
            print(f'--- {name}\n{text}', file=sys.stderr)
    assert not failures, [f[:5] for f in failures]


def _catches_sigterm(pid: int) -> bool:
    """Whether the process has a SIGTERM handler (``SigCgt`` of /proc): the entry module's,
    installed with its SIGINT one - Python itself catches only SIGINT."""
    for line in Path(f'/proc/{pid}/status').read_text().splitlines():
        if line.startswith('SigCgt:'):
            return bool(int(line.split()[1], 16) >> (signal.SIGTERM - 1) & 1)
    return False


def _start_one(name: str, params: Path, run_dir: Path, env: dict) -> subprocess.Popen:
    """One node as ``ros2 run``/``ros2 launch`` start it (the console script's entry)."""
    extra = ['-p', f'output:={run_dir / "bag"}'] if name == 'recorder' else []
    with open(run_dir / f'{name}.log', 'w') as log:
        return subprocess.Popen([sys.executable, '-m', 'nonfragile_tracker.nodes.entry', name,
                                 '--ros-args', '--params-file', str(params), *extra],
                                env=env, stdout=log, stderr=subprocess.STDOUT,
                                stdin=subprocess.DEVNULL, process_group=0)


@pytest.mark.ros
def test_signal_during_start_up_ends_every_node_cleanly(tmp_path, ros_env):
    """Ctrl-C right after ``ros2 launch`` starts, ``systemctl stop`` during boot: a signal
    while a node is still importing numpy/rclpy, in ``rclpy.init`` (before rclpy's
    handlers exist) or building the node ends it with 0 and no traceback - it was a
    KeyboardInterrupt traceback, or lost (a recorder that never ended: seen with the real
    launch).  Each signal is sent once the entry module's handlers are in place (seen in
    /proc: the interpreter's own start-up before them is the one window left), after a
    fraction of the node's start-up time measured here."""
    params = write_parameter_file(scenario_parameters(
        CONFIG / 'paper_scenario.yaml', CONFIG / 'tracker_gains.yaml',
        {n: {'ros__parameters': {'mode': 'realtime'}} for n in ('plant', 'tracker',
                                                                 'reference')}),
        tmp_path / 'params.yaml')
    startup = {}                                  # to 'started', on this machine now
    for name in NODES:
        run_dir = tmp_path / f'measure_{name}'
        run_dir.mkdir()
        t0 = time.monotonic()
        p = _start_one(name, params, run_dir, ros_env)
        while 'started;' not in (run_dir / f'{name}.log').read_text():
            assert p.poll() is None and time.monotonic() - t0 < 60, \
                (run_dir / f'{name}.log').read_text()
            time.sleep(0.005)
        startup[name] = time.monotonic() - t0
        p.send_signal(signal.SIGINT)
        assert p.wait(30) == 0, (name, p.returncode, (run_dir / f'{name}.log').read_text())
    trials = [(name, sig, frac) for name in NODES
              for sig, frac in ((signal.SIGINT, 0.15), (signal.SIGINT, 0.45),
                                (signal.SIGTERM, 0.7), (signal.SIGINT, 0.95))]

    def trial(k: int):
        name, sig, frac = trials[k]
        run_dir = tmp_path / f'{name}_{k}'
        run_dir.mkdir()
        p = _start_one(name, params, run_dir, ros_env)
        t0 = time.monotonic()
        while not _catches_sigterm(p.pid):             # the entry module's first lines ran
            assert p.poll() is None and time.monotonic() - t0 < 30
            time.sleep(0.001)
        time.sleep(frac * startup[name])
        os.killpg(p.pid, sig)                           # the terminal: the node's group
        try:
            code = p.wait(30)
        except subprocess.TimeoutExpired:
            kill_with_stacks(p)
            code = 'hung'
        return name, sig.name, frac, code, (run_dir / f'{name}.log').read_text()

    with ThreadPoolExecutor(max_workers=4) as pool:
        results = list(pool.map(trial, range(len(trials))))
    bad = [(n, s, f, c, text[-1200:]) for n, s, f, c, text in results
           if c != 0 or _bad(text)]
    assert not bad, (startup, bad)


@pytest.mark.ros
def test_sigkill_recorder_mid_run_then_repair(tmp_path, ros_env):
    """The recorder is killed (SIGKILL) mid-run: ``bag repair`` recovers a readable bag."""
    launch = Launch(tmp_path, 'realtime', ros_env)
    try:
        launch.wait_ready()
        time.sleep(0.8)                                   # a few flushes (every 0.2 s)
        launch.procs['recorder'].kill()
        assert launch.procs['recorder'].wait(10) == -signal.SIGKILL
        os.killpg(launch.pgid, signal.SIGINT)             # the others end as usual
        codes, _ = launch.wait()
    finally:
        launch.kill()
    assert {n: c for n, c in codes.items() if n != 'recorder'} == \
        {'tracker': 0, 'reference': 0, 'plant': 0}
    assert not (launch.bag / 'metadata.yaml').exists()
    out = subprocess.run([sys.executable, '-m', 'nonfragile_tracker.cli', 'bag', 'repair',
                          str(launch.bag)], capture_output=True, text=True, env=ros_env,
                         cwd=ROOT, timeout=60)
    assert out.returncode == 0 and 'Traceback' not in out.stderr, out.stderr
    repaired = tmp_path / 'bag_repaired'
    data = read_bag(repaired)
    assert data.counts['/odom'] > 10 and data.counts['/cmd_vel'] > 10, data.counts
    assert mcap_is_complete(next(repaired.glob('*.mcap')))


@pytest.mark.ros
def test_callback_running_into_a_shutdown_ends_quietly():
    """rclpy's signal thread may shut the context down while a callback publishes: the
    node's guarded callbacks end quietly (no exception out of the executor)."""
    import rclpy
    from geometry_msgs.msg import PoseStamped
    from rclpy.impl.implementation_singleton import rclpy_implementation as impl

    from nonfragile_tracker.nodes.common import overrides
    from nonfragile_tracker.nodes.reference import ReferenceNode
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=unique_domain_id("quietly"))
    node = ReferenceNode(context=ctx, parameter_overrides=overrides(mode='realtime'))
    try:
        node.timer.callback()                       # publishes three messages: fine
        ctx.try_shutdown()                          # what SIGINT/SIGTERM do, from a thread
        with pytest.raises(impl.RCLError, match='context is invalid'):
            node.pub_pose.publish(PoseStamped())    # a bare publish raises now ...
        assert node.timer.callback() is None        # ... the guarded callback does not
    finally:
        node.destroy_node()


@pytest.mark.ros
def test_sigusr1_dumps_the_stacks_and_the_node_goes_on(tmp_path, ros_env):
    """SIGUSR1 (what the runner and these tests send before killing a node that did not
    end) writes where every thread is into the node's log; the node keeps running and still
    ends with 0 on SIGINT."""
    p = _start_one('reference', CONFIG / 'paper_scenario.yaml', tmp_path, ros_env)
    try:
        t0 = time.monotonic()
        while 'started;' not in (tmp_path / 'reference.log').read_text():
            assert p.poll() is None and time.monotonic() - t0 < 60
            time.sleep(0.01)
        p.send_signal(signal.SIGUSR1)
        t0 = time.monotonic()
        while 'in spin_until' not in (tmp_path / 'reference.log').read_text():
            assert p.poll() is None and time.monotonic() - t0 < 10, \
                (tmp_path / 'reference.log').read_text()
            time.sleep(0.01)
        time.sleep(0.3)
        assert p.poll() is None                              # a dump, not an end
        p.send_signal(signal.SIGINT)
        assert p.wait(30) == 0
    finally:
        kill_with_stacks(p)
    text = (tmp_path / 'reference.log').read_text()
    assert 'nodes/common.py' in text and 'in run' in text and 'Traceback' not in text
