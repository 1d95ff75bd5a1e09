#!/usr/bin/env python3
"""Issue 38: one row through the ROS nodes in real time, beside the adapter's figure.

    .venv/bin/python benchmarks/peers_ros.py [--latencies 0,0.1] [--seeds 1,2,3]
        [--controllers ours,ltv] [--mode realtime|lockstep] [--json PATH] [--keep DIR]
        [--from-json PATH]

The adapter (:func:`peers.adapter.run`) runs every controller of ``benchmarks/peers.py``
in process.  This script shows that it is the same loop as the nodes: WPILib's stock
``LTVUnicycleController`` (``peers.wpilib:ltv``, named by the tracker node's ``controller``
parameter, ``benchmarks/`` on the nodes' ``PYTHONPATH``) and our shipped default (the
node's default controller, shipped gain, no predictor) each run through the real nodes
(reference, plant, tracker, recorder; one process per node, ``runner.run_processes``) in
real time (wall timers, ``runner.realtime_overrides``) on the benchmark's realistic base
(``config/latency_scenario.yaml`` with :data:`peers.adapter.REALISTIC`: 50 ms lag on v
and w, 1 m/s^2 and 3 rad/s^2, 50 Hz odometry with 1 mm / 1 mrad noise; clamps 1 m/s and
2 rad/s in the tracker node), the figure eight r = 1 m at 0.2 rad/s from 10 cm beside it,
40 s.  The recorded bag is scored as the adapter scores a run: the time-indexed error of
the true pose (``/pose``) against the recorded reference (interpolated at the pose
stamps) after 10 s from the plant's first step, RMS and max; diverged above 0.25 m.

Beside it, the adapter's figures for the same cell and seeds: with the table's 10 ms
command-latency jitter (``peers.py``'s cell), without it (the plant node has no
command-jitter parameter: the base the node was given), and at ``L + 10 ms`` and
``L + 20 ms``.  In real time a command acts one plant step later than in lockstep: the
plant's wall tick publishes the odometry of step k and steps on with the command in force,
so the tracker's answer acts from step k + 1 at the earliest (``L + 10 ms``), from k + 2
when it misses the next tick (``L + 20 ms``; the machine's load), later after a stall.  A
real-time figure agrees with the adapter when it lies in that band (10 % either side: the
seeds' spread and the stalls beyond a tick), or when both diverge (:data:`BAND`).
``--mode lockstep`` runs the nodes in lockstep instead: there the figures must equal the
adapter's without jitter to round-off.

Run inside a network namespace of your own; each run takes its own ROS_DOMAIN_ID
(``runner.reserved_domain``).  Runs go one at a time (a parallel run would add its own
jitter).
"""
from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
for _p in (HERE, ROOT, ROOT / 'test'):
    if str(_p) not in sys.path:
        sys.path.insert(0, str(_p))

from peers import adapter  # noqa: E402  (benchmarks/peers/, the package)


def _load_table_script():
    """``benchmarks/peers.py`` (the table's script; the package ``peers`` shadows its name)."""
    import importlib.util
    spec = importlib.util.spec_from_file_location('peers_table_script', HERE / 'peers.py')
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod
    spec.loader.exec_module(mod)
    return mod


peers_bench = _load_table_script()

CONFIG = ROOT / 'config'
DURATION = 40.0
SETTLE = 10.0
START = (0.0, -0.1, math.pi / 4, 0.0)
#: label -> (tracker node ``controller`` parameter or None for the default, peers.py label)
CONTROLLERS = {'ours': (None, peers_bench.OURS_DEFAULT),
               'ltv': ('peers.wpilib:ltv', 'WPILib LTV')}
ZERO_PREDICT = {'predict_latency': 0.0, 'predict_odom_latency': 0.0, 'predict_lag_v': 0.0,
                'predict_lag_w': 0.0}


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


#: Real time, ``--reference trajectory``: the eight as a timed waypoint file (10 ms knots),
#: which the reference node publishes as a trajectory starting this long after its start
#: and the tracker samples at each odometry stamp, as the adapter does.
START_DELAY = 3.0


def eight_file() -> Path:
    """The figure eight r 1 m at 0.2 rad/s as a waypoint file (t, x, y, yaw, speed; 10 ms)."""
    from nonfragile_tracker.control.simulation.reference import figure_eight
    path = Path(tempfile.gettempdir()) / 'nfpeers_ros_eight.csv'
    eight = figure_eight(radius=1.0, rate=0.2)
    t = np.arange(0.0, DURATION + 5.0 + 1e-9, 0.01)
    rows = ['t,x,y,yaw,speed']
    for ti in t:
        r = eight.sample(float(ti))
        rows.append(f'{ti:.2f},{r.x!r},{r.y!r},{r.heading!r},{math.hypot(r.vx, r.vy)!r}')
    text = '\n'.join(rows) + '\n'
    if not path.exists() or path.read_text() != text:
        path.write_text(text)
    return path


def file_trajectory():
    """The trajectory the tracker rebuilds from the reference node's Path of :func:`eight_file`."""
    from nonfragile_tracker.nodes.trajectory_io import path_to_trajectory, trajectory_to_path
    from nonfragile_tracker.control.simulation.trajectory import load_waypoints
    traj, _ = path_to_trajectory(trajectory_to_path(load_waypoints(eight_file()), 0, 'odom'),
                                 frame='odom', source='eight')
    return traj


def node_parameters(controller: str | None, latency: float, seed: int,
                    mode: str = 'realtime', reference: str = 'samples') -> dict:
    """The four nodes' parameters of one run (``mode``: realtime or lockstep; ``reference``:
    the built-in path's samples, or the eight as a trajectory file, :func:`eight_file`)."""
    from nonfragile_tracker.workflows import runner
    r = adapter.REALISTIC
    plant = {'cmd_latency': latency, 'noise_seed': seed, 'duration': DURATION,
             'initial_pose': list(START[:3]), 'initial_speed': START[3], 'odom_rate': 50.0,
             'lag_v': r['lag_v'], 'lag_w': r['lag_w'],
             'max_linear_accel': r['max_linear_accel'],
             'max_angular_accel': r['max_angular_accel'], 'odom_noise': list(r['odom_noise'])}
    tracker = dict(ZERO_PREDICT, **peers_bench.scenario_tracker())
    if controller:
        tracker['controller'] = controller
    ov = {'plant': {'ros__parameters': plant}, 'tracker': {'ros__parameters': tracker}}
    if reference == 'trajectory':
        ov['reference'] = {'ros__parameters': {'trajectory_file': str(eight_file()),
                                               'start_delay': START_DELAY}}
    if mode == 'realtime':
        runner.merge(ov, runner.realtime_overrides())
    return runner.scenario_parameters(CONFIG / 'latency_scenario.yaml',
                                      CONFIG / 'tracker_gains.yaml', ov)


#: A second window, from 20 s: the start transients of both over (see the module doc).
SETTLE_LATE = 20.0


def bag_figures(bag: Path, settle: float = SETTLE) -> dict:
    """Time-indexed true-pose error after ``settle`` s (and after :data:`SETTLE_LATE` s: keys
    ending in ``_late``) from the plant's first pose: RMS, max (m); the reference's lead
    (s: how long before the plant's first step its time started), and the command period's
    median / p99 / max (ms) as the bag saw it."""
    from nonfragile_tracker.bag.reader import read_bag, read_messages
    run = read_bag(bag, strict=False).run
    ref = run.reference
    rows = [(m.header.stamp.sec * 10**9 + m.header.stamp.nanosec, m.pose.position.x,
             m.pose.position.y) for _, m in read_messages(bag, 'pose')]
    ps, px, py = (np.array(c, dtype=float) for c in zip(*rows))
    rs = ref.stamp_ns.astype(float)
    out = {'span_s': float((ps[-1] - ps[0]) * 1e-9), 'ref_lead_s': float((ps[0] - rs[0]) * 1e-9)}
    t0 = ps[0]          # a trajectory (--reference trajectory) starts at its stamp: from there
    from nonfragile_tracker.bag.reader import MissingTopicsError
    try:
        for _, msg in read_messages(bag, 'trajectory'):
            t0 = max(t0, float(msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec))
            out['trajectory_start_s'] = float((t0 - ps[0]) * 1e-9)
            break
    except MissingTopicsError:      # the built-in path's samples: from the first pose
        pass
    for sfx, after in (('', settle), ('_late', SETTLE_LATE)):
        keep = (ps >= t0 + after * 1e9) & (ps >= rs[0]) & (ps <= rs[-1])
        e = np.hypot(px[keep] - np.interp(ps[keep], rs, ref.x),
                     py[keep] - np.interp(ps[keep], rs, ref.y))
        out['rms' + sfx] = float(np.sqrt(np.mean(e * e))) if e.size else math.nan
        out['max' + sfx] = float(e.max()) if e.size else math.nan
        out['diverged' + sfx] = (not math.isfinite(out['rms' + sfx])
                                 or out['max' + sfx] > adapter.DIVERGED)
    cs = np.asarray(run.commands.stamp_ns, dtype=float)
    if cs.size > 2:
        d = np.diff(cs) * 1e-6
        out.update(cmd_period_med_ms=float(np.median(d)),
                   cmd_period_p99_ms=float(np.percentile(d, 99)),
                   cmd_period_max_ms=float(d.max()), commands=int(cs.size))
    return out


def ros_run(controller: str | None, latency: float, seed: int, run_dir: Path,
            mode: str = 'realtime', reference: str = 'samples') -> dict:
    """One run through the nodes (every topic recorded), scored (or ``error``)."""
    from nonfragile_tracker.workflows import runner
    params = node_parameters(controller, latency, seed, mode, reference)
    if reference == 'trajectory':       # time for the start delay
        params['plant']['ros__parameters']['duration'] = DURATION + START_DELAY
    run_dir.mkdir(parents=True)
    pp = os.pathsep.join([str(HERE)] + ([os.environ['PYTHONPATH']]
                                        if os.environ.get('PYTHONPATH') else []))
    env = {k: v for k, v in os.environ.items() if k != 'ROS_DOMAIN_ID'}
    env['PYTHONPATH'] = pp
    t0 = time.perf_counter()
    try:
        res = runner.run_processes(params, run_dir, record=True, env=env, timeout=300.0,
                                   progress=lambda _line: None, record_all=True)
    except Exception as exc:          # noqa: BLE001 - one bad run must not hide the rest
        return {'error': repr(exc)}
    out = {'exit_codes': res.exit_codes, 'wall_s': time.perf_counter() - t0}
    if any(c not in (0, None, -2) for c in res.exit_codes.values()):
        out['error'] = 'exit codes ' + str(res.exit_codes) + ' ' + ' | '.join(
            runner.log_tail(run_dir, n, 5) for n in res.exit_codes)[-1500:]
        return out
    try:
        out.update(bag_figures(res.bag))
    except Exception as exc:          # noqa: BLE001
        out['error'] = repr(exc)
    return out


def adapter_run(label: str, latency: float, seed: int, jitter: bool,
                reference: str = 'samples') -> dict:
    """The adapter's figures of a cell (peers.py's base at ``latency``; ``jitter``: with
    its 10 ms command-latency jitter, else none; ``reference`` 'trajectory': the eight of
    :func:`eight_file` as the tracker rebuilds it)."""
    from nonfragile_tracker.control.simulation.reference import figure_eight
    from nonfragile_tracker.control.simulation.trajectory import Trajectory
    over = {} if jitter else {'cmd_latency_jitter': 0.0}
    pc = adapter.base_plant(round(latency, 6), 50.0, seed, START, **over)
    peers, _ = peers_bench.discover_peers()
    if label in peers_bench.OURS:
        tc = peers_bench.our_config(label, pc)
    else:
        from nonfragile_tracker.control.simulation.gains import read_gain_file
        from nonfragile_tracker.control.simulation.tracker import TrackerConfig
        tc = TrackerConfig(K=read_gain_file(CONFIG / 'tracker_gains.yaml'),
                           **peers_bench.scenario_tracker())
    traj = (file_trajectory() if reference == 'trajectory' else
            Trajectory.analytic(figure_eight(radius=1.0, rate=0.2)))
    pr = adapter.run(peers_bench._factory(label, peers), pc, tc, traj, DURATION)
    s, late = adapter.score(pr, SETTLE), adapter.score(pr, SETTLE_LATE)
    return {'rms': s.rms, 'max': s.max, 'diverged': s.diverged, 'rms_late': late.rms,
            'max_late': late.max, 'diverged_late': late.diverged}


def _mm(x: float) -> str:
    if not math.isfinite(x):
        return 'nan'
    x *= 1e3
    return f'{x:.3g}' if x < 100 else f'{x:.0f}'


def _cell(rs: list[dict], sfx: str = '') -> str:
    ok = [r for r in rs if 'rms' + sfx in r]
    if not ok:
        return 'failed'
    med = statistics.median(r['rms' + sfx] for r in ok)
    div = sum(bool(r['diverged' + sfx]) for r in ok)
    spread = f'{_mm(min(r["rms" + sfx] for r in ok))}-{_mm(max(r["rms" + sfx] for r in ok))}'
    return (f'{"div %d/%d " % (div, len(ok)) if div else ""}{_mm(med)} ({spread}; max '
            f'{_mm(statistics.median(r["max" + sfx] for r in ok))})')


#: The adapter's columns: (key, latency offset s, jitter).  ``step``: a real-time loop's
#: one plant step between the odometry of step k going out and its answer taking effect
#: (the plant's wall tick publishes step k, then steps on with the command in force; the
#: answer acts from step k + 1 at the earliest).  Lockstep has no such step.
ADAPTER_COLUMNS = (('table', 0.0, True), ('exact', 0.0, False), ('step', 0.01, False),
                   ('step_jitter', 0.01, True), ('two_steps', 0.02, False))
COLUMN_TITLES = {'table': 'adapter, the table\'s cell (L, +0/10 ms jitter)',
                 'exact': 'adapter, L (no jitter: the node\'s base)',
                 'step': 'adapter, L + 10 ms',
                 'step_jitter': 'adapter, L + 10 ms, +0/10 ms jitter',
                 'two_steps': 'adapter, L + 20 ms'}
#: The band a real-time run must fall in: between the adapter at L + 10 ms (every answer in
#: time for the next tick) and at L + 20 ms (every answer one tick late), 10 % either side
#: (the seeds' own spread and the few stalls beyond a tick).
BAND = (('step', 0.9), ('two_steps', 1.1))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--latencies', default='0,0.1', help='command latencies (s), comma list')
    ap.add_argument('--seeds', default='1,2,3', help='noise seeds, comma list')
    ap.add_argument('--controllers', default='ours,ltv', help=f'of {sorted(CONTROLLERS)}')
    ap.add_argument('--mode', choices=('realtime', 'lockstep'), default='realtime',
                    help='the nodes on wall timers (default) or in lockstep (must equal the '
                    'adapter without jitter to round-off)')
    ap.add_argument('--reference', choices=('samples', 'trajectory'), default='samples',
                    help='the built-in eight\'s samples (default; in real time the tracker '
                    'takes the newest, 0-10 ms old, and the path starts at the reference '
                    'node\'s start) or the eight as a trajectory file, sampled by the tracker '
                    f'at each odometry stamp as the adapter does, starting {START_DELAY:g} s '
                    'after the reference node')
    ap.add_argument('--json', help='every run\'s figures as JSON')
    ap.add_argument('--keep', help='keep the run folders (bags, logs) here')
    ap.add_argument('--from-json', help='the nodes\' figures of an earlier --json (no runs '
                    'through the nodes; the adapter columns computed again)')
    args = ap.parse_args(argv)
    old = json.loads(Path(args.from_json).read_text()) if args.from_json else {}
    lats = [float(x) for x in args.latencies.split(',')]
    seeds = [int(x) for x in args.seeds.split(',')]
    ctrls = [c.strip() for c in args.controllers.split(',')]
    cols = ADAPTER_COLUMNS if args.mode == 'realtime' else ADAPTER_COLUMNS[:2]
    tmp = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix='nfpeers_ros_'))
    tmp.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    raw: dict = {}
    for c in ctrls:
        spec, label = CONTROLLERS[c]
        for lat in lats:
            for seed in seeds:
                key = f'{c}/{lat:g}/{seed}'
                log(f'{key}: the adapter, then the nodes ({args.mode}, {DURATION:g} s)')
                raw[key] = {k: adapter_run(label, lat + off, seed, jit, args.reference)
                            for k, off, jit in cols}
                run_dir = tmp / (f'{args.mode}_' + key.replace('/', '_'))
                if old and (run_dir / 'bag').exists():       # score the kept bag again
                    raw[key]['ros'] = {**old[key]['ros'], **bag_figures(run_dir / 'bag')}
                else:
                    raw[key]['ros'] = old[key]['ros'] if old else ros_run(
                        spec, lat, seed, run_dir, args.mode, args.reference)
                r = raw[key]['ros']
                if 'rms' in r:
                    msg = (f"{r['rms'] * 1e3:.3f} mm (max {r['max'] * 1e3:.2f}), command "
                           f"period median {r.get('cmd_period_med_ms', math.nan):.1f} / p99 "
                           f"{r.get('cmd_period_p99_ms', math.nan):.1f} / max "
                           f"{r.get('cmd_period_max_ms', math.nan):.1f} ms")
                else:
                    msg = r.get('error', '?')
                log(f'  nodes: {msg}; adapter ' + ', '.join(
                    f"{k} {raw[key][k]['rms'] * 1e3:.3f}" for k, _, _ in cols) + ' mm')
    for sfx, after in (('', SETTLE), ('_late', SETTLE_LATE)):
        print(f'figure eight r 1 m at 0.2 rad/s, 50 Hz odometry, realistic base, command latency '
              f'L; time-indexed true-pose RMS after {after:g} s, mm: median of seeds '
              f'{args.seeds} (min-max; median of the max)\n')
        print(f'| controller | L ms | ROS nodes, {args.mode} | '
              + ' | '.join(COLUMN_TITLES[k] for k, _, _ in cols) + ' | nodes / adapter |'
              + (' in the band |' if args.mode == 'realtime' else ''))
        print('|---' * (4 + len(cols) + (args.mode == 'realtime')) + '|')
        ref_col = 'step' if args.mode == 'realtime' else 'exact'
        for c in ctrls:
            for lat in lats:
                rs = [raw[f'{c}/{lat:g}/{s}'] for s in seeds]
                ros = [r['ros'] for r in rs]
                ok = [r for r in ros if 'rms' + sfx in r]
                ratio = (statistics.median(r['rms' + sfx] for r in ok)
                         / statistics.median(r[ref_col]['rms' + sfx] for r in rs)) if ok else math.nan
                band = ''
                if args.mode == 'realtime' and ok:
                    m = statistics.median(r['rms' + sfx] for r in ok)
                    (k0, f0), (k1, f1) = BAND
                    lo = f0 * statistics.median(r[k0]['rms' + sfx] for r in rs)
                    hi = f1 * statistics.median(r[k1]['rms' + sfx] for r in rs)
                    div_ros = all(r['diverged' + sfx] for r in ok)
                    div_ad = all(r[k0]['diverged' + sfx] and r[k1]['diverged' + sfx] for r in rs)
                    band = (' both diverge |' if div_ros and div_ad else
                            f' {"yes" if lo <= m <= hi and not (div_ros or div_ad) else "NO"} '
                            f'({_mm(lo)}-{_mm(hi)}) |')
                print(f'| {CONTROLLERS[c][1]} | {lat * 1e3:g} | {_cell(ros, sfx)} | '
                      + ' | '.join(_cell([r[k] for r in rs], sfx) for k, _, _ in cols)
                      + f' | {ratio:.3g} ({ref_col}) |' + band)
        print()
    if args.mode == 'lockstep':
        worst = max((abs(r['ros']['rms'] - r['exact']['rms']) for r in raw.values()
                     if 'rms' in r['ros']), default=math.nan)
        print(f'largest |RMS(nodes) - RMS(adapter)| over the runs: {worst * 1e3:.3g} mm')
    leads = [r['ros']['ref_lead_s'] for r in raw.values() if 'ref_lead_s' in r['ros']]
    if leads and args.mode == 'realtime':
        print(f'the reference\'s time started {min(leads):.2f}-{max(leads):.2f} s before the '
              f'plant\'s first step (median {statistics.median(leads):.2f} s; in process: 0)')
    periods = [r['ros'] for r in raw.values() if 'cmd_period_p99_ms' in r['ros']]
    if periods and args.mode == 'realtime':
        print(f'\ncommand period in the bags (50 Hz odometry, 20 ms nominal): median '
              f'{statistics.median(p["cmd_period_med_ms"] for p in periods):.1f} ms, p99 '
              f'{statistics.median(p["cmd_period_p99_ms"] for p in periods):.1f} ms (median '
              f'over runs), worst gap {max(p["cmd_period_max_ms"] for p in periods):.0f} ms; '
              f'load average at the end {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs')
    print(f'({time.perf_counter() - t0:.0f} s wall)')
    if args.json:
        Path(args.json).write_text(json.dumps(raw, indent=1, default=str))
    if not args.keep:
        shutil.rmtree(tmp, ignore_errors=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
