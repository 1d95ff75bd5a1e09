"""Issue 31: one ``bringup`` per unknown base, then the tracker with the files it wrote.

The bases (this package's plant, real time, odometry 50 Hz with 1 mm / 1 mrad noise):
command latency 40, 100, 200, 300 ms x lag 30, 80 ms x acceleration limits 1 m/s^2 /
3 rad/s^2 and 0.5 m/s^2 / 1.5 rad/s^2 (16 bases).  For each base and repetition:

1. ``bringup --simulate SCENARIO --accel-segment`` (real time, the default 1 m box and
   0.3 m/s, 1 rad/s): robot time, farthest distance from the start pose, the identified
   latency against the truth (within one odometry period: the real-time plant adds up to
   one plant step, 10 ms, to the configured latency) and the lags (within 20 %);
2. with the gain file and robot file it wrote: the figure eight r = 1 m at 0.2 rad/s
   (``run``, lockstep, 40 s; RMS position error after 10 s against the odometry, target
   2 mm) and the line-arc lap (``run --trajectory config/trajectories/line_arc_lap.csv``,
   lockstep; cross-track RMS while the trajectory is active, target 3 mm).

``--ctrlc N``: N bring-ups (on the 100 ms base) stopped by a SIGINT to the process group
(a terminal's Ctrl-C) at a random moment of a random phase (excite, analyse, trial): the
last command in the bag is zero within 0.1 s of the signal and no process is left.
``--refusal``: a base whose latency jumps between 0.1 and 0.6 s: the bring-up must refuse
naming the latency, and write no gain.

Usage::

    .venv/bin/python benchmarks/bringup.py [--bases all|LAT/LAG/ACC,...] [--reps 3]
        [--ctrlc 20] [--refusal] [--out DIR]

``LAT/LAG/ACC`` e.g. ``100/30/1`` (ms, ms, 1 = 1 m/s^2 / 3 rad/s^2, 0.5 = 0.5 / 1.5).  The
whole grid (16 bases x 3 repetitions, about 4 min each) takes about 3 h.  Prints one
table (median over the repetitions) and writes ``DIR/bringup.json``.  ROS runs go through
``unshare -n`` (a private network namespace) when it is available.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import random
import re
import shutil
import signal
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
LATENCY_SCENARIO = ROOT / 'config' / 'latency_scenario.yaml'
LINE_ARC_SCENARIO = ROOT / 'config' / 'line_arc_scenario.yaml'
LAP = ROOT / 'config' / 'trajectories' / 'line_arc_lap.csv'
LATENCIES = (40, 100, 200, 300)
LAGS = (30, 80)
LIMITS = {1.0: (1.0, 3.0), 0.5: (0.5, 1.5)}
TARGET_FIG8, TARGET_LAP, TARGET_ROBOT_TIME = 0.002, 0.003, 90.0
#: The phases a Ctrl-C trial picks from (--ctrlc-phases).
PHASES = ['excite', 'analyse', 'trial']


def _netns(cmd: list[str]) -> list[str]:
    if shutil.which('unshare') and os.geteuid() == 0:
        inner = ' '.join(f"'{c}'" for c in cmd)
        return ['unshare', '-n', 'sh', '-c', f'ip link set lo up; exec {inner}']
    return cmd


def cli(*args: str, log: Path | None = None, check: bool = True) -> subprocess.CompletedProcess:
    """Run the package's CLI in a network namespace of its own."""
    cmd = _netns([sys.executable, '-m', 'nonfragile_tracker.cli', *args])
    res = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    if log is not None:
        log.write_text(res.stdout + res.stderr)
    if check and res.returncode != 0:
        raise RuntimeError(f'{" ".join(args)} failed ({res.returncode}):\n{res.stdout[-3000:]}\n'
                           f'{res.stderr[-3000:]}')
    return res


def base_plant(latency_ms: float, lag_ms: float, acc: float, seed: int) -> dict:
    lin, ang = LIMITS[acc]
    return {'cmd_latency': latency_ms / 1000.0, 'lag_v': lag_ms / 1000.0,
            'lag_w': lag_ms / 1000.0, 'max_linear_accel': lin, 'max_angular_accel': ang,
            'odom_rate': 50.0, 'odom_noise': [0.001, 0.001, 0.001], 'noise_seed': seed}


def scenario(src: Path, dst: Path, plant: dict, tracker: dict | None = None) -> Path:
    data = yaml.safe_load(src.read_text())
    data['/**/plant']['ros__parameters'].update(plant)
    data['/**/tracker']['ros__parameters'].update(tracker or {})
    dst.write_text(yaml.safe_dump(data))
    return dst


def rms_after(bag: Path, after: float) -> float:
    """RMS position error (against the odometry) after ``after`` s, within the reference."""
    from nonfragile_tracker.bag.reader import read_bag
    d = read_bag(bag, strict=False)
    p, r = d.run.pose, d.run.reference
    xr, yr = np.interp(p.t, r.t, r.x), np.interp(p.t, r.t, r.y)
    sel = (p.t - p.t[0] > after) & (p.t >= r.t[0]) & (p.t <= r.t[-1])
    return float(np.sqrt(np.mean((p.x[sel] - xr[sel]) ** 2 + (p.y[sel] - yr[sel]) ** 2)))


def cross_track_rms(bag: Path) -> float:
    """Cross-track RMS (against the odometry) while the trajectory is active."""
    from nonfragile_tracker.bag.reader import read_bag
    from nonfragile_tracker.bag.report import bag_report
    d = read_bag(bag, strict=False)
    p, r = d.run.pose, d.run.reference
    rep = bag_report(bag, plots=False)
    t0, t1 = rep.phases.active_span if rep.phases is not None else (p.t[0], p.t[-1])
    sel = (p.t - p.t[0] >= t0) & (p.t - p.t[0] <= t1) & (p.t >= r.t[0]) & (p.t <= r.t[-1])
    xr, yr = np.interp(p.t, r.t, r.x), np.interp(p.t, r.t, r.y)
    vx, vy = np.interp(p.t, r.t, r.vx), np.interp(p.t, r.t, r.vy)
    th = np.arctan2(vy, vx)
    moving = np.hypot(vx, vy) > 1e-3
    cross = -(p.x - xr) * np.sin(th) + (p.y - yr) * np.cos(th)
    sel &= moving
    return float(np.sqrt(np.mean(cross[sel] ** 2)))


#: The bring-up's odometry timeout here (s).  The default (the robot file's input_timeout,
#: 0.5 s) stops a bring-up whose odometry stalls that long - which the real-time plant does
#: on this shared 2-core machine at load 15-20; --odom-timeout sets it.
ODOM_TIMEOUT = 0.5


def one_base(out: Path, lat: float, lag: float, acc: float, rep: int) -> dict:
    name = f'base_{lat:g}_{lag:g}_{acc:g}_{rep}'
    d = out / name
    d.mkdir(parents=True, exist_ok=True)
    plant = base_plant(lat, lag, acc, seed=rep)
    sc = scenario(LATENCY_SCENARIO, d / 'scenario.yaml', plant)
    t0 = time.monotonic()
    res = cli('bringup', '--simulate', str(sc), '--accel-segment', '--out', str(d), '--name',
              'bringup', '--odom-timeout', str(ODOM_TIMEOUT), log=d / 'bringup.log',
              check=False)
    row: dict = {'base': f'{lat:g} ms / {lag:g} ms / {acc:g}', 'rep': rep,
                 'exit': res.returncode, 'wall_s': time.monotonic() - t0}
    text = res.stdout
    m = re.search(r'robot time ([\d.]+) s; farthest ([\d.]+) m', text)
    if m:
        row.update(robot_time=float(m.group(1)), farthest=float(m.group(2)))
    analysis = d / 'bringup' / 'analysis.json'
    if res.returncode != 0 or not analysis.exists():
        row['error'] = text[-1500:] + res.stderr[-1500:]
        return row
    o = json.loads(analysis.read_text())
    if not o.get('ok'):
        row['error'] = o.get('refusal')
        return row
    row.update(latency=o['latency_s'], latency_err=o['latency_s'] - lat / 1000.0,
               tau_v=o['tau_v_s'], tau_w=o['tau_w_s'],
               lag_err=max(abs(o['tau_v_s'] / (lag / 1000.0) - 1),
                           abs(o['tau_w_s'] / (lag / 1000.0) - 1)),
               accel=[o['max_linear_accel'], o['max_angular_accel']],
               gain_norm=o['gain_norm'])
    gains = Path(o['gain_file'])
    robot = yaml.safe_load(Path(o['robot_file']).read_text())['/**/tracker']['ros__parameters']
    limits = {k: robot[k] for k in ('max_linear_accel', 'max_angular_accel') if robot[k] > 0}
    fig8 = scenario(LATENCY_SCENARIO, d / 'fig8.yaml', plant, limits)
    cli('run', '--scenario', str(fig8), '--gains', str(gains), '--duration', '40', '--out',
        str(d), '--name', 'fig8', log=d / 'fig8.log')
    row['fig8_rms_after_10s'] = rms_after(d / 'fig8' / 'bag', 10.0)
    lap = scenario(LINE_ARC_SCENARIO, d / 'lap.yaml', plant, limits)
    cli('run', '--scenario', str(lap), '--gains', str(gains), '--trajectory', str(LAP),
        '--out', str(d), '--name', 'lap', log=d / 'lap.log')
    row['lap_cross_track_rms'] = cross_track_rms(d / 'lap' / 'bag')
    return row


def ctrlc_trial(out: Path, k: int, rng: random.Random, phase: str | None = None) -> dict:
    """One bring-up stopped by SIGINT to its process group in a random (or the given)
    phase, at a random moment of it."""
    from nonfragile_tracker.bag.motion import read_motion
    d = out / f'ctrlc_{k}'
    d.mkdir(parents=True, exist_ok=True)
    sc = scenario(LATENCY_SCENARIO, d / 'scenario.yaml', base_plant(100, 30, 1.0, seed=k))
    phase = phase or rng.choice(PHASES)
    cmd = _netns([sys.executable, '-m', 'nonfragile_tracker.cli', 'bringup', '--simulate',
                  str(sc), '--out', str(d), '--name', 'run', '--odom-timeout',
                  str(ODOM_TIMEOUT)])
    log = open(d / 'out.log', 'w')
    p = subprocess.Popen(cmd, cwd=ROOT, stdout=log, stderr=subprocess.STDOUT, text=True,
                         start_new_session=True)
    deadline = time.monotonic() + 400
    while time.monotonic() < deadline and p.poll() is None:
        if f'phase {phase}' in (d / 'out.log').read_text():
            break
        time.sleep(0.05)
    time.sleep(rng.uniform(0.0, {'excite': 40.0, 'analyse': 5.0, 'trial': 15.0}[phase]))
    sent = time.time()
    os.killpg(p.pid, signal.SIGINT)
    try:
        code = p.wait(timeout=30)
    except subprocess.TimeoutExpired:
        code = None
    log.close()
    time.sleep(0.5)
    try:
        os.killpg(p.pid, 0)
        left = True
    except ProcessLookupError:
        left = False
    bags = [b for b in (d / 'run' / 'trial_bag', d / 'run' / 'bag') if b.exists()]
    row = {'trial': k, 'phase': phase, 'exit': code, 'left_running': left}
    if bags:
        c = read_motion(bags[0]).commands
        row.update(last_v=float(c.v[-1]), last_w=float(c.w[-1]),
                   delay=float(c.t[-1]) - sent)
    if left:
        ps = subprocess.run(['ps', '-o', 'pid,stat,args', '-g', str(p.pid)], capture_output=True,
                            text=True)
        row['left'] = ps.stdout[-2000:]
        os.killpg(p.pid, signal.SIGKILL)
    return row


def design_or_refusal(d: Path, plant: dict) -> dict:
    """One bring-up without a trial on ``plant``: designed for, or refused (the line)."""
    d.mkdir(parents=True, exist_ok=True)
    sc = scenario(LATENCY_SCENARIO, d / 'scenario.yaml', plant)
    res = cli('bringup', '--simulate', str(sc), '--out', str(d), '--name', 'run',
              '--trial-duration', '0', '--odom-timeout', str(ODOM_TIMEOUT),
              log=d / 'bringup.log', check=False)
    line = next((ln for ln in res.stdout.splitlines() if 'REFUSED' in ln), '')
    m = re.search(r'robot time ([\d.]+) s; farthest ([\d.]+) m', res.stdout)
    return {'exit': res.returncode, 'refusal': line, 'names_latency': 'latency' in line,
            'gain_written': (d / 'run' / 'gains.yaml').exists(),
            'farthest': float(m.group(2)) if m else None, 'tail': res.stdout[-600:]}


def refusal(out: Path) -> dict:
    """A base whose latency jumps between 0.1 and 0.6 s every 3 s: refused, naming it."""
    sched = []
    for i in range(1, 40):
        sched += [3.0 * i, 0.6 if i % 2 else 0.1]
    return design_or_refusal(out / 'refusal', {**base_plant(100, 30, 1.0, 1),
                                               'cmd_latency_schedule': sched})


def steady(out: Path, lat_ms: float) -> dict:
    """A base with a steady latency of ``lat_ms`` (lag 80 ms, 1 m/s^2 / 3 rad/s^2): the
    bring-up either designs a gain certified for it (the predictor takes the latency, the
    certificate the residual) or refuses, and says which."""
    return {'latency_ms': lat_ms, **design_or_refusal(out / f'steady_{lat_ms:g}',
                                                      base_plant(lat_ms, 80, 1.0, 1))}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--bases', default='100/30/1,300/80/0.5',
                    help="'all' or LAT/LAG/ACC,... (default two bases)")
    ap.add_argument('--reps', type=int, default=1)
    ap.add_argument('--ctrlc', type=int, default=0)
    ap.add_argument('--refusal', action='store_true')
    ap.add_argument('--steady', default='',
                    help='steady latencies (ms, comma-separated) beyond the shipped gain\'s: '
                    'designed for or refused (see steady())')
    ap.add_argument('--out', default='/tmp/bringup_bench')
    ap.add_argument('--odom-timeout', type=float, default=0.5,
                    help='the bring-up\'s odometry timeout (s; default 0.5, the robot file '
                    'default): raise it on a loaded machine whose plant stalls')
    ap.add_argument('--ctrlc-phases', default='excite,analyse,trial',
                    help='the phases a Ctrl-C trial picks from')
    ap.add_argument('--ctrlc-each-phase', action='store_true',
                    help='--ctrlc N trials in each phase (not N in random phases)')
    ap.add_argument('--jobs', type=int, default=1,
                    help='bring-ups at once (each in a network namespace of its own; the '
                    'real-time plant stamps the time of its motion, so a loaded machine '
                    'shifts no figure, but a stall beyond --odom-timeout stops a run)')
    args = ap.parse_args()
    PHASES[:] = args.ctrlc_phases.split(',')
    global ODOM_TIMEOUT
    ODOM_TIMEOUT = args.odom_timeout
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    if args.bases == 'all':
        bases = [(la, lg, ac) for la in LATENCIES for lg in LAGS for ac in LIMITS]
    elif args.bases:
        bases = [tuple(float(x) for x in b.split('/')) for b in args.bases.split(',')]
    else:
        bases = []
    results: dict = {'date': time.strftime('%Y-%m-%d %H:%M:%S'), 'load': os.getloadavg(),
                     'odom_timeout': ODOM_TIMEOUT,
                     'bases': [], 'ctrlc': [], 'refusal': None}
    path = out / 'bringup.json'

    def done(key: str, row: dict) -> None:
        results[key].append(row)
        print(json.dumps(row, default=float), file=sys.stderr, flush=True)
        path.write_text(json.dumps(results, indent=1, default=float))

    from concurrent.futures import ThreadPoolExecutor
    with ThreadPoolExecutor(max_workers=max(1, args.jobs)) as pool:
        for f in [pool.submit(one_base, out, lat, lag, acc, rep)
                  for lat, lag, acc in bases for rep in range(1, args.reps + 1)]:
            done('bases', f.result())
        # each trial its own generator: the same moments whatever the number of jobs
        trials = ([(k, PHASES[k % len(PHASES)]) for k in range(args.ctrlc * len(PHASES))]
                  if args.ctrlc_each_phase else [(k, None) for k in range(args.ctrlc)])
        for f in [pool.submit(ctrlc_trial, out, k, random.Random(31_000 + k), phase)
                  for k, phase in trials]:
            done('ctrlc', f.result())
    if args.refusal:
        results['refusal'] = refusal(out)
        print(json.dumps(results['refusal']), file=sys.stderr, flush=True)
    results['steady'] = []
    for lat in [float(x) for x in args.steady.split(',') if x]:
        results['steady'].append(steady(out, lat))
        print(json.dumps(results['steady'][-1]), file=sys.stderr, flush=True)
    results['load_end'] = os.getloadavg()
    path.write_text(json.dumps(results, indent=1, default=float))
    _table(results)
    return 0


def _med(rows: list[dict], key: str) -> float:
    vals = [r[key] for r in rows if isinstance(r.get(key), (int, float))]
    return statistics.median(vals) if vals else math.nan


def _table(results: dict) -> None:
    print('| base (latency / lag / accel) | n | robot time s | farthest m | latency err ms | '
          'lag err % | fig-8 RMS mm | lap cross-track RMS mm |')
    print('|---|---|---|---|---|---|---|---|')
    by: dict = {}
    for r in results['bases']:
        by.setdefault(r['base'], []).append(r)
    for base, rows in by.items():
        ok = [r for r in rows if 'error' not in r]
        print(f'| {base} | {len(ok)}/{len(rows)} | {_med(ok, "robot_time"):.1f} | '
              f'{max((r.get("farthest", math.nan) for r in rows), default=math.nan):.3f} | '
              f'{1e3 * _med(ok, "latency_err"):+.1f} | {100 * _med(ok, "lag_err"):.0f} | '
              f'{1e3 * _med(ok, "fig8_rms_after_10s"):.2f} | '
              f'{1e3 * _med(ok, "lap_cross_track_rms"):.2f} |')
    if results['ctrlc']:
        rows = results['ctrlc']
        zero = sum(1 for r in rows if r.get('last_v') == 0.0 and r.get('last_w') == 0.0)
        by_signal = [r for r in rows if r['exit'] == 130]
        driving = [r for r in by_signal if r['phase'] != 'analyse']
        prompt = sum(1 for r in driving if 0.0 <= r.get('delay', math.nan) <= 0.1)
        delays = sorted(1e3 * r['delay'] for r in driving if 'delay' in r)
        left = sum(1 for r in rows if r['left_running'])
        others = sorted(r['exit'] for r in rows if r['exit'] != 130)
        shown = ', '.join(f'{d:.1f}' for d in delays)
        print(f'Ctrl-C: {len(rows)} trials, {len(by_signal)} ended by the signal (the others '
              f'stopped before it: {others}); last command zero {zero}/{len(rows)}; driving '
              f'when signalled {len(driving)}, zero within 0.1 s {prompt}/{len(driving)} '
              f'(delays {shown} ms); at rest (analyse) {len(by_signal) - len(driving)}; '
              f'processes left {left}')
        print('| phase | trials | ended by the signal | last command zero | zero within 0.1 s '
              '(driving) | signal -> zero command ms (median, max) | processes left |')
        print('|---|---|---|---|---|---|---|')
        for phase in dict.fromkeys(r['phase'] for r in rows):
            pr = [r for r in rows if r['phase'] == phase]
            sig = [r for r in pr if r['exit'] == 130]
            ms = [1e3 * r['delay'] for r in sig if 'delay' in r and phase != 'analyse']
            print(f'| {phase} | {len(pr)} | {len(sig)} | '
                  f'{sum(1 for r in pr if r.get("last_v") == 0.0 and r.get("last_w") == 0.0)} | '
                  + (f'{sum(1 for d in ms if 0.0 <= d <= 100.0)}/{len(ms)} | '
                     f'{statistics.median(ms):.1f}, {max(ms):.1f} | ' if ms else
                     '- (at rest) | - | ')
                  + f'{sum(1 for r in pr if r["left_running"])} |')
    if results['refusal']:
        print(f'refusal: {results["refusal"]}')
    for r in results.get('steady', []):
        print(f'steady latency {r["latency_ms"]:g} ms: exit {r["exit"]}, gain written '
              f'{r["gain_written"]}, farthest {r["farthest"]} m, {r["refusal"] or "designed"}')


if __name__ == '__main__':
    sys.exit(main())
