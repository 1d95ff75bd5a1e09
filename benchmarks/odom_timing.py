#!/usr/bin/env python3
"""The tracker's step from the odometry stamps against the paper's 10 ms told by hand (issue 30).

    .venv/bin/python benchmarks/odom_timing.py [--seeds 3] [--duration 40] [--json PATH]

Issue 30's "what it must show": defaults only (no ``dt`` set for the tracker, no predictor,
the tracker's limit parameters unknown, the shipped ``config/tracker_gains.yaml``), figure
eight r = 1 m at 0.2 rad/s on the package's plant with the realistic options (50 ms lag
on v and w, limits 1 m/s^2 and 3 rad/s^2, 1 mm / 1 mrad odometry noise), the robot at rest
10 cm beside the start, command latency 100 and 150 ms, odometry at 20, 50 and 100 Hz and at
50 Hz with 5 ms jitter (``odom_jitter``; plant step 1 ms for that row, 10 ms otherwise).
Columns: "today" - the tracker as shipped before issue 30, its step the paper's 10 ms
(``dt: 0.01``, which ``config/paper_scenario.yaml`` and ``robot.launch.py`` loaded) - and
"new default" (``dt: 0``, the step from the odometry stamps).  Figure: RMS position error
(true pose vs reference) after 10 s in mm, median over ``--seeds`` noise seeds (1..N) with
the worst in brackets; targets 10 mm at 100 ms and 15 mm at 150 ms (new default).

Default: in process (:func:`control.simulation.simulate.simulate_tracking`, the nodes' step
functions in the lockstep order: a lockstep ROS run gives the same numbers to 1e-9).

    .venv/bin/python benchmarks/odom_timing.py --nodes [--mode realtime] [--jobs 2]

The same through the nodes (``config/latency_scenario.yaml`` with the overrides above, one
process per node, ``runner.run_processes``), in real time by default (wall timers,
``runner.realtime_overrides``) or ``--mode lockstep``; RMS of ``/pose`` against the recorded
reference after 10 s (:func:`latency.bag_rms_after`).  Real time on a loaded machine is
noisy: read the load average printed with the table.  Prints one table; not a test.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import sys
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
for p in (ROOT, ROOT / 'benchmarks'):
    if str(p) not in sys.path:
        sys.path.insert(0, str(p))

from nonfragile_tracker.control.simulation.gains import read_gain_file  # noqa: E402
from nonfragile_tracker.control.simulation.plant import PlantConfig
from nonfragile_tracker.control.simulation.tracker import TrackerConfig  # noqa: E402
from nonfragile_tracker.control.simulation.reference import figure_eight  # noqa: E402
from nonfragile_tracker.control.simulation.simulate import simulate_tracking  # noqa: E402

CONFIG = ROOT / 'config'
GAINS = CONFIG / 'tracker_gains.yaml'
#: The realistic base (issue 22's): lags, limits, noise.
BASE = dict(lag_v=0.05, lag_w=0.05, max_linear_accel=1.0, max_angular_accel=3.0,
            odom_noise=(0.001, 0.001, 0.001))
START = (0.0, -0.1, math.pi / 4)
#: Rows: (label, odometry rate Hz, jitter s, plant step s).
ROWS = (('20 Hz', 20.0, 0.0, 0.01), ('50 Hz', 50.0, 0.0, 0.01), ('100 Hz', 100.0, 0.0, 0.01),
        ('50 Hz, 5 ms jitter', 50.0, 0.005, 0.001))
LATENCIES = (0.1, 0.15)
TARGET_MM = {0.1: 10.0, 0.15: 15.0}
#: Columns: (label, the tracker's dt).
COLUMNS = (('today (dt 0.01)', 0.01), ('new default (dt 0)', 0.0))
AFTER = 10.0


def run_inprocess(dt: float, rate: float, jitter: float, plant_dt: float, latency: float,
                  seed: int, duration: float) -> float:
    """RMS error (m) after 10 s of one in-process run."""
    pc = PlantConfig(dt=plant_dt, x0=START[0], y0=START[1], th0=START[2], cmd_latency=latency,
                     odom_rate=rate, odom_jitter=jitter, noise_seed=seed, **BASE)
    with warnings.catch_warnings():
        warnings.simplefilter('ignore')          # "today" disagrees with the odometry: warned
        run = simulate_tracking(pc, TrackerConfig(K=read_gain_file(GAINS), dt=dt),
                                figure_eight(radius=1.0, rate=0.2),
                                int(round(duration / plant_dt)))
    e = run.error[run.t > AFTER]
    return float(np.sqrt(np.mean(e * e)))


def node_run(job: dict) -> dict:
    """One run through the nodes; the job with its ``rms_m``."""
    from latency import bag_rms_after
    from nonfragile_tracker.workflows import runner
    plant = {'cmd_latency': job['latency'], 'noise_seed': job['seed'],
             'duration': job['duration'], 'initial_pose': list(START), 'initial_speed': 0.0,
             'dt': job['plant_dt'], 'odom_rate': job['rate'], 'odom_jitter': job['jitter'],
             **{k: (list(v) if isinstance(v, tuple) else v) for k, v in BASE.items()}}
    tracker = {'predict_latency': 0.0, 'predict_odom_latency': 0.0, 'predict_lag_v': 0.0,
               'predict_lag_w': 0.0, 'dt': job['dt']}
    ov = {'plant': {'ros__parameters': plant}, 'tracker': {'ros__parameters': tracker}}
    if job['mode'] == 'realtime':
        runner.merge(ov, runner.realtime_overrides())
    params = runner.scenario_parameters(CONFIG / 'latency_scenario.yaml', GAINS, ov)
    run_dir = Path(job['dir'])
    run_dir.mkdir(parents=True)
    env = runner.isolated_env({**os.environ, 'ROS_DOMAIN_ID': str(job['domain'])})
    out = {**job, 'rms_m': math.nan}
    try:
        res = runner.run_processes(params, run_dir, record=True, env=env, timeout=300.0,
                                   progress=lambda _line: None, record_all=True)
        out['exit_codes'] = res.exit_codes
        out['rms_m'] = bag_rms_after(res.bag, job['duration'], AFTER)
    except Exception as exc:          # noqa: BLE001 - one bad run must not hide the table
        out['error'] = repr(exc)
    return out


def node_runs(args, jobs: list[dict]) -> list[dict]:
    """``jobs`` through the nodes, ``--jobs`` at a time, each on a domain id of its own."""
    import queue
    import shutil
    import tempfile
    from concurrent.futures import ThreadPoolExecutor
    tmp = Path(tempfile.mkdtemp(prefix='nfodt_'))
    free: queue.Queue = queue.Queue()
    for d in range(args.domain, args.domain + args.jobs):
        free.put(d)
    for i, j in enumerate(jobs):
        j['dir'] = str(tmp / f'run{i:03d}')

    def go(job):
        job['domain'] = free.get()
        try:
            return node_run(job)
        finally:
            free.put(job['domain'])
    try:
        with ThreadPoolExecutor(args.jobs) as ex:
            return list(ex.map(go, jobs))
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def cell(values_m: list[float]) -> str:
    mm = [v * 1e3 for v in values_m]
    if not mm or any(math.isnan(v) for v in mm):
        return 'failed'
    return f'{statistics.median(mm):6.1f} ({max(mm):5.1f})'


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--seeds', type=int, default=3)
    ap.add_argument('--duration', type=float, default=40.0)
    ap.add_argument('--nodes', action='store_true', help='through the nodes')
    ap.add_argument('--mode', choices=('realtime', 'lockstep'), default='realtime')
    ap.add_argument('--jobs', type=int, default=1, help='--nodes: runs at a time')
    ap.add_argument('--domain', type=int, default=215 + os.getpid() % 18)
    ap.add_argument('--rows', default='', help='comma list of row numbers (1-4) to run')
    ap.add_argument('--json', default='')
    args = ap.parse_args(argv)
    rows = [ROWS[int(i) - 1] for i in args.rows.split(',') if i] or list(ROWS)
    t0 = time.perf_counter()
    load0 = os.getloadavg()
    cases = [(r, lat, col, dt, seed) for r in rows for lat in LATENCIES
             for col, dt in COLUMNS for seed in range(1, args.seeds + 1)]
    results: dict[tuple, list[float]] = {}
    if args.nodes:
        jobs = [{'row': r[0], 'rate': r[1], 'jitter': r[2], 'plant_dt': r[3], 'latency': lat,
                 'col': col, 'dt': dt, 'seed': seed, 'duration': args.duration,
                 'mode': args.mode} for r, lat, col, dt, seed in cases]
        print(f'{len(jobs)} runs of {args.duration:g} s through the nodes ({args.mode}), '
              f'{args.jobs} at a time ...', file=sys.stderr, flush=True)
        done = node_runs(args, jobs)
        for j in done:
            results.setdefault((j['row'], j['latency'], j['col']), []).append(j['rms_m'])
            if 'error' in j:
                print(f"  {j['row']} {j['latency']} {j['col']} seed {j['seed']}: {j['error']}",
                      file=sys.stderr)
        raw = done
        how = f'through the nodes, {args.mode}'
    else:
        raw = []
        for r, lat, col, dt, seed in cases:
            rms = run_inprocess(dt, r[1], r[2], r[3], lat, seed, args.duration)
            results.setdefault((r[0], lat, col), []).append(rms)
            raw.append({'row': r[0], 'latency': lat, 'col': col, 'seed': seed, 'rms_m': rms})
        how = 'in process (the lockstep sequence)'
    load1 = os.getloadavg()
    print(f'Issue 30: defaults only, figure eight r 1 m at 0.2 rad/s, 50 ms lag, 1 m/s^2 and '
          f'3 rad/s^2, 1 mm noise; {how}; RMS after {AFTER:g} s (mm), median of '
          f'{args.seeds} (worst); {args.duration:g} s runs; load {load0[0]:.1f} -> '
          f'{load1[0]:.1f}')
    head = f"{'odometry':20s} {'latency':>8s}  " + '  '.join(f'{c:>18s}' for c, _ in COLUMNS) \
        + '   target  new default'
    print(head)
    print('-' * len(head))
    for r in rows:
        for lat in LATENCIES:
            cells = [cell(results[(r[0], lat, c)]) for c, _ in COLUMNS]
            new = results[(r[0], lat, COLUMNS[-1][0])]
            med = statistics.median(new) * 1e3 if new else math.nan
            verdict = 'MET' if med <= TARGET_MM[lat] else 'MISSED'
            print(f'{r[0]:20s} {1e3 * lat:6.0f} ms  ' + '  '.join(f'{c:>18s}' for c in cells)
                  + f'  <= {TARGET_MM[lat]:4.0f}  {verdict}')
    print(f'({time.perf_counter() - t0:.0f} s wall)')
    if args.json:
        Path(args.json).write_text(json.dumps({'how': how, 'runs': raw, 'load': [load0, load1]},
                                              indent=1, default=str))
    return 0


if __name__ == '__main__':
    sys.exit(main())
