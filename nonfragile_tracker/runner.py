"""The main job: run a scenario through the ROS nodes, record a bag, report.

``nonfragile_tracker run`` starts the recorder, tracker, reference and plant as
separate processes (what ``ros2 launch`` does) or composed in this process on
one executor (``--composed``), in deterministic lockstep on simulation time,
shows progress, then writes a report with plots next to the bag.

The ROS environment is kept on this host (ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST)
on a domain id of its own unless the caller set ROS_DOMAIN_ID.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import yaml

NODES = ('tracker', 'reference', 'plant')


def isolated_env(base: dict | None = None) -> dict:
    """Environment for a run: localhost discovery and a domain id of our own, unless set."""
    env = dict(os.environ if base is None else base)
    env.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    env.setdefault('ROS_DOMAIN_ID', str(100 + os.getpid() % 100))
    env.setdefault('PYTHONUNBUFFERED', '1')
    pkg_root = str(Path(__file__).resolve().parent.parent)
    env['PYTHONPATH'] = pkg_root + (os.pathsep + env['PYTHONPATH'] if env.get('PYTHONPATH')
                                     else '')
    return env


def _merge(dst: dict, src: dict) -> dict:
    for k, v in src.items():
        if isinstance(v, dict) and isinstance(dst.get(k), dict):
            _merge(dst[k], v)
        else:
            dst[k] = v
    return dst


def node_key(key: str) -> str:
    """Node name of a parameter-file key: ``tracker``, ``/tracker`` and ``/**/tracker`` -> tracker."""
    for prefix in ('/**/', '/'):
        if key.startswith(prefix):
            return key[len(prefix):]
    return key


def scenario_parameters(scenario: Path, gains: Path | None, overrides: dict | None = None
                        ) -> dict:
    """One parameter mapping {node: {'ros__parameters': {...}}} from the files and overrides.

    File keys may be ``node``, ``/node`` or ``/**/node`` (any namespace); the mapping uses
    the bare node name and :func:`write_parameter_file` writes ``/**/node`` again.
    """
    params: dict = {}
    for path in (scenario, gains):
        if path is None:
            continue
        data = yaml.safe_load(Path(path).read_text()) or {}
        _merge(params, {node_key(k): v for k, v in data.items()})
    _merge(params, overrides or {})
    return params


def write_parameter_file(params: dict, path: Path) -> Path:
    """ROS 2 parameter file with ``/**/node`` keys, so namespaced nodes match too."""
    path.write_text(yaml.safe_dump({f'/**/{k}': v for k, v in _doubles(params).items()},
                                   sort_keys=False))
    return path


@dataclass
class RunResult:
    run_dir: Path
    bag: Path | None
    exit_codes: dict
    wall_time: float
    steps: int


def new_run_dir(root: Path, name: str | None) -> Path:
    from .bag.writer import new_run_dir as _new
    return _new(root, name)


def _doubles(value):
    """Lists mixing ints and floats are written as doubles (rcl rejects mixed sequences)."""
    if isinstance(value, dict):
        return {k: _doubles(v) for k, v in value.items()}
    if isinstance(value, list) and any(isinstance(v, float) for v in value):
        return [float(v) if isinstance(v, int) and not isinstance(v, bool) else v for v in value]
    return value


def run_processes(params: dict, run_dir: Path, *, record: bool = True, env: dict | None = None,
                  timeout: float = 600.0, progress=print,
                  recorder_topics: list[str] | None = None) -> RunResult:
    """Run the scenario with one process per node; returns exit codes per node.

    Each node's output goes to ``<run_dir>/<node>.log``; the plant's progress lines
    are passed to ``progress``.  If a node dies before the plant has finished, the
    run is stopped at once (its exit code tells which).
    """
    env = isolated_env(env)
    params_file = write_parameter_file(params, run_dir / 'params.yaml')
    py = sys.executable
    procs: dict[str, subprocess.Popen] = {}
    logs: dict[str, object] = {}
    bag = run_dir / 'bag' if record else None
    t0 = time.monotonic()

    def start(name: str, extra: list[str] = ()) -> None:
        cmd = [py, '-m', f'nonfragile_tracker.nodes.{name}', '--ros-args', '--params-file',
               str(params_file), *extra]
        logs[name] = open(run_dir / f'{name}.log', 'w')
        procs[name] = subprocess.Popen(cmd, env=env, stdout=logs[name],
                                       stderr=subprocess.STDOUT, text=True)

    def report_plant(reader, final: bool = False) -> None:
        for line in reader.readlines():
            line = line.rstrip()
            if 'progress:' in line or 'ERROR' in line or 'FATAL' in line or 'complete' in line:
                progress(f'[plant] {line.split("] ", 1)[-1] if "] " in line else line}')

    try:
        if record:
            extra = ['-p', f'output:={bag}', '-p', 'use_sim_time:=true', '-p',
                     'lockstep_gate:=true']
            if recorder_topics:
                extra += ['-p', 'topics:=[' + ','.join(f"'{t}'" for t in recorder_topics) + ']']
            start('recorder', extra)
        start('tracker')
        start('reference')
        start('plant', ['-p', f'lockstep_subscribers:={2 if record else 1}'])
        plant = procs['plant']
        with open(run_dir / 'plant.log') as reader:
            while plant.poll() is None:
                report_plant(reader)
                # the recorder closes its bag and exits 0 right after run_done, which can be
                # before the plant's last poll here: that is the end of the run, not a death
                dead = {n: p.returncode for n, p in procs.items()
                        if n != 'plant' and p.poll() is not None
                        and not (n == 'recorder' and p.returncode == 0)}
                if dead:
                    progress(f'[runner] node(s) exited early: {dead}; stopping the run '
                             f'(logs in {run_dir})')
                    break
                if time.monotonic() - t0 > timeout:
                    progress('[runner] timeout: stopping the run')
                    break
                time.sleep(0.05)
            report_plant(reader)
        if plant.poll() is not None and record:
            try:
                procs['recorder'].wait(timeout=30)
            except subprocess.TimeoutExpired:
                procs['recorder'].send_signal(signal.SIGINT)
                procs['recorder'].wait(timeout=30)
    finally:
        for name, p in procs.items():
            if p.poll() is None:
                p.send_signal(signal.SIGINT)
        for name, p in procs.items():
            try:
                p.wait(timeout=10)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
        for fh in logs.values():
            fh.close()
    codes = {name: p.returncode for name, p in procs.items()}
    steps = int(round(params['plant']['ros__parameters'].get('duration', 60.0)
                      / params['plant']['ros__parameters'].get('dt', 0.01)))
    return RunResult(run_dir, bag, codes, time.monotonic() - t0, steps)


def run_composed(params: dict, run_dir: Path | None, *, record: bool = True,
                 timeout: float = 600.0, recorder_topics: list[str] | None = None) -> RunResult:
    """Run the scenario with all nodes in this process on one executor."""
    import rclpy
    from rclpy.parameter import Parameter

    from .nodes.common import make_executor
    from .nodes.plant import PlantNode
    from .nodes.reference import ReferenceNode
    from .nodes.tracker import TrackerNode

    def overrides(name: str, extra: dict | None = None) -> list:
        vals = dict(params.get(name, {}).get('ros__parameters', {}))
        vals.update(extra or {})
        return [Parameter(k, value=v) for k, v in vals.items()]

    t0 = time.monotonic()
    # a private context on a domain of our own (localhost discovery): no cross-talk
    env = isolated_env()
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', env['ROS_AUTOMATIC_DISCOVERY_RANGE'])
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=int(env['ROS_DOMAIN_ID']))
    nodes = []
    bag = None
    try:
        if record:
            from .nodes.recorder import Recorder
            bag = run_dir / 'bag'
            rec_params = {'output': str(bag), 'use_sim_time': True, 'lockstep_gate': True}
            if recorder_topics:
                rec_params['topics'] = list(recorder_topics)
            nodes.append(Recorder(context=ctx, **rec_params))
        nodes.append(TrackerNode(parameter_overrides=overrides('tracker'), context=ctx))
        nodes.append(ReferenceNode(parameter_overrides=overrides('reference'), context=ctx))
        plant = PlantNode(context=ctx, parameter_overrides=overrides(
            'plant', {'lockstep_subscribers': 2 if record else 1}))
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


def add_subcommands(sub) -> None:
    """Add ``run`` to the CLI (``bag`` is :mod:`nonfragile_tracker.commands.bag`)."""
    r = sub.add_parser('run', help='the main job: paper scenario through the ROS nodes, '
                       'bag, report and plots')
    r.add_argument('--scenario', help='node parameter file (default config/paper_scenario.yaml)')
    r.add_argument('--gains', help='tracker gain file (default config/tracker_gains.yaml)')
    r.add_argument('--duration', type=float, help='simulated seconds (default: scenario, 60)')
    r.add_argument('--delta', choices=['Delta_1', 'Delta_2'],
                   help="inject the paper's gain perturbation (E Delta F) into the tracker")
    r.add_argument('--delay-compensation', action='store_true',
                   help='zero steady-state error law (delay-consistent reference)')
    r.add_argument('--path', choices=['circle', 'figure_eight'], help='reference path')
    r.add_argument('--composed', action='store_true',
                   help='all nodes in this process (default: one process per node)')
    r.add_argument('--out', default='runs', help='directory for run directories (default runs/)')
    r.add_argument('--name', help='run directory name (default run_<date>_<time>)')
    r.add_argument('--no-record', action='store_true', help='do not record a bag')
    r.set_defaults(func=cmd_run)



DELTAS = {'Delta_1': [-1.0, 0.0, 0.0, -1.0], 'Delta_2': [1.0, 0.0, 0.0, 1.0]}


def cmd_run(args) -> int:
    from .cli import config_dir
    scenario = Path(args.scenario) if args.scenario else config_dir() / 'paper_scenario.yaml'
    gains = Path(args.gains) if args.gains else config_dir() / 'tracker_gains.yaml'
    ov: dict = {'plant': {'ros__parameters': {}}, 'tracker': {'ros__parameters': {}},
                'reference': {'ros__parameters': {}}}
    if args.duration is not None:
        ov['plant']['ros__parameters']['duration'] = float(args.duration)
    if args.delta:
        ov['tracker']['ros__parameters']['Delta'] = DELTAS[args.delta]
    if args.delay_compensation:
        ov['tracker']['ros__parameters']['delay_compensation'] = True
    if args.path:
        ov['reference']['ros__parameters']['path'] = args.path
    params = scenario_parameters(scenario, gains, ov)
    from .control.gains import read_gain_file
    read_gain_file(gains)           # refuse a bad gain before starting anything (exit 2)
    run_dir = new_run_dir(Path(args.out), args.name)
    record = not args.no_record
    dur = params['plant']['ros__parameters'].get('duration')
    print(f'run directory: {run_dir}')
    print(f'scenario {scenario.name}, gains {gains.name}, {dur} s simulated, '
          f'{"composed" if args.composed else "one process per node"}, lockstep')
    if args.composed:
        res = run_composed(params, run_dir, record=record)
    else:
        res = run_processes(params, run_dir, record=record)
    bad = {k: v for k, v in res.exit_codes.items() if v not in (0, None, -2)}
    print(f'wall time {res.wall_time:.1f} s ({res.steps / max(res.wall_time, 1e-9):.0f} steps/s '
          'including start-up)')
    if bad:
        print(f'error: node(s) failed: {bad}; logs in {run_dir}', file=sys.stderr)
        return 5
    if record:
        from .bag.report import bag_report, format_report
        rep = bag_report(res.bag, run_dir)
        print(format_report(rep))
        print(f'bag: {res.bag}\nplots and summary: {run_dir}')
    return 0
