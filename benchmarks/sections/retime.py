"""Benchmark section: R. Re-timing within a base's limits (issue 30, item 3).

Waypoint files as loggers and planners write them (``test/planner_files.py``: sampled
every 0.05 s in time with a trapezoidal speed, the goal appended 4 ms after the last
sample): the rounded rectangle 3 x 1.5 m with 0.4 m arcs at 0.4 m/s (0.3 m/s^2 ramps),
the same without the appended goal, an S (0.6 m arcs, 0.3 m/s) driven backwards, and the
shipped lap ``config/trajectories/line_arc_lap.csv`` (points every 5 cm along the path).
With the base's limits (1 m/s, 1 m/s^2, 2 rad/s, 3 rad/s^2) each is re-timed by
:func:`control.simulation.limits.retime` today (the module as of commit ``BEFORE``, loaded
from git) and now, beside toppra's time-optimal duration on the now-fitted geometry
(``test/toppra_oracle.py``; toppra 0.6.10, test-only).  Then the wall and CPU time of a
re-timing of a 63.7 s trajectory (three laps of the rectangle, 1,275 points), and the
rectangle and the S followed in process on issue 23's base as planned, re-timed today and
now (R.8).

    .venv/bin/python benchmarks/run.py --only retime
    .venv/bin/python benchmarks/sections/retime.py [--quick]      # this section alone
"""
from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
for p in (HERE.parent, ROOT / 'test'):
    if str(p) not in sys.path:
        sys.path.insert(0, str(p))

from harness import Table, fmt, log, spread, summary  # noqa: E402

#: The package before issue 30 item 3 (its re-timing is "today").
BEFORE = '0cce4da'
#: Re-timing of a 60 s trajectory must take less (s): the robot waits for it.
RETIME_BUDGET = 0.2


def _module_before():
    """``control.simulation.limits`` as of commit BEFORE, or None (no git, no commit)."""
    try:
        text = subprocess.run(['git', '-C', str(ROOT), 'show',
                               f'{BEFORE}:nonfragile_tracker/control/simulation/limits.py'],
                              capture_output=True, text=True, check=True, timeout=30).stdout
    except (OSError, subprocess.SubprocessError):
        return None
    tmp = Path(tempfile.mkdtemp(prefix='nf_retime_')) / 'limits_before.py'
    tmp.write_text(text)
    name = 'nonfragile_tracker.control.simulation._limits_before'
    spec = importlib.util.spec_from_file_location(name, tmp)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod
    spec.loader.exec_module(mod)
    return mod


def cases() -> dict:
    """The trajectories of the section, by name."""
    import planner_files as pf
    from nonfragile_tracker.control.simulation.trajectory import from_waypoints, load_waypoints

    def traj(rows, name):
        return from_waypoints(rows['t'], rows['x'], rows['y'], yaw=rows['yaw'],
                              speed=rows['speed'], source=name)
    rect = pf.sample(pf.rounded_rectangle())
    return {
        'rectangle 3 x 1.5 m, 0.05 s + goal': traj(rect, 'rectangle'),
        'rectangle, without the goal': traj({k: v[:-1] for k, v in rect.items()},
                                            'rectangle without goal'),
        'S backwards, 0.05 s + goal': traj(pf.sample(pf.s_curve(), speed=0.3, backwards=True),
                                           'S backwards'),
        'shipped lap (points every 5 cm)': load_waypoints(ROOT / 'config' / 'trajectories' /
                                                          'line_arc_lap.csv'),
    }


def long_trajectory():
    """Three laps of the rectangle as a logger writes them (63.7 s, 1,275 points)."""
    import planner_files as pf
    from nonfragile_tracker.control.simulation.trajectory import from_waypoints
    rows = pf.sample(pf.rounded_rectangle(laps=3))
    return from_waypoints(rows['t'], rows['x'], rows['y'], yaw=rows['yaw'],
                          speed=rows['speed'], source='rectangle x3')


def bench_retime(cfg, table: Table, raw: dict) -> None:
    from nonfragile_tracker.control.simulation.limits import Limits, check, retime
    base = Limits(max_linear_speed=1.0, max_linear_accel=1.0, max_angular_speed=2.0,
                  max_angular_accel=3.0)
    before = _module_before()
    try:
        import toppra_oracle
        import toppra  # noqa: F401
    except ImportError:
        toppra_oracle = None
    out: dict = {'limits': base.__dict__, 'before_commit': BEFORE, 'cases': {}}
    worst = 0.0
    for k, (name, tr) in enumerate(cases().items(), 1):
        log(f'retime: {name}')
        r = retime(tr, base)
        again = check(r.trajectory, base, tolerance=0.01)
        excess = max(rep.peak / rep.limit for rep in again.reports[:4] if rep.limit > 0)
        worst = max(worst, excess)
        opt = toppra_oracle.duration(r.path, base) if toppra_oracle else float('nan')
        today = before.retime(tr, before.Limits(**base.__dict__)) if before else None
        t_today = today.duration_after if today else float('nan')
        ratio = r.duration_after / opt
        out['cases'][name] = {'planned': tr.duration, 'today': t_today,
                              'now': r.duration_after, 'toppra': opt, 'ratio': ratio,
                              'deviation_m': r.path.deviation if r.path else 0.0,
                              'peaks_after': {rep.name: rep.peak for rep in again.reports}}
        peaks = (f"{fmt(again['max_linear_accel'].peak)} m/s^2, "
                 f"{fmt(again['max_angular_accel'].peak)} rad/s^2, turn rate "
                 f"{fmt(again['max_angular_speed'].peak)} rad/s")
        table.add(f'R.{k}', f'lap time (s, 4 digits in the detail), {name}',
                  r.duration_after, 's',
                  f'planned {fmt(tr.duration, 4)} s; today {fmt(t_today, 4)} s; toppra '
                  f'{fmt(opt, 4)} s; after: {peaks}; path within '
                  f'{fmt((r.path.deviation if r.path else 0.0) * 1e3)} mm',
                  f'x{fmt(ratio, 4)} toppra (today x{fmt(t_today / opt)})',
                  target='retime_optimal', check=ratio)
    table.add('R.5', 'worst peak / limit after re-timing (R.1-R.4)', worst, 'x limit',
              'check(..., tolerance=0.01) of the re-timed trajectory, accelerations over 20 ms',
              target='retime_limits')
    # time of a re-timing of a 60 s trajectory
    tr = long_trajectory()
    reps = 3 if cfg.quick else 7
    retime(tr, base)                                       # warm-up (imports, caches)
    walls, cpus = [], []
    for _ in range(reps):
        w0, c0 = time.perf_counter(), time.process_time()
        r = retime(tr, base)
        walls.append(time.perf_counter() - w0)
        cpus.append(time.process_time() - c0)
    w, c = summary(walls), summary(cpus)
    if before:
        w0 = time.perf_counter()
        old = before.retime(tr, before.Limits(**base.__dict__))
        t_old, d_old = time.perf_counter() - w0, old.duration_after
    else:
        t_old = d_old = float('nan')
    out['long'] = {'duration': tr.duration, 'points': int(tr.knots.size), 'wall_s': w,
                   'cpu_s': c, 'retimed': r.duration_after, 'today_wall_s': t_old,
                   'today_retimed': d_old, 'loadavg': os.getloadavg()}
    table.add('R.6', f're-timing of a {fmt(tr.duration)} s trajectory ({tr.knots.size:,} '
              'points)', w['median'], 's',
              f"{spread(w)}; CPU {fmt(c['median'])} s; re-timed {fmt(tr.duration, 4)} -> "
              f"{fmt(r.duration_after, 4)} s (today {fmt(d_old, 4)} s); load "
              f"{fmt(os.getloadavg()[0])}",
              f'today {fmt(t_old)} s', target='retime_60s')
    table.add('R.7', 're-timing of the same, CPU time (= wall time on an idle core)',
              c['median'], 's', f"{spread(c)}; the wall time above is this stretched by the "
              f"machine's load", '', target='retime_60s')
    out['tracking'] = _tracking(table, before)
    raw['retime'] = out


def _tracking(table: Table, before) -> dict:
    """R.8: the files followed in process on issue 23's base (config/line_arc_scenario.yaml:
    40 ms latency, 50 ms lags, 1 m/s^2 and 3 rad/s^2 in the plant; no odometry noise) with
    the shipped gain and the scenario's predictor: as planned, re-timed today, re-timed now.
    Error: position against the (re-timed) reference while it is active."""
    import math

    import numpy as np
    import yaml

    from nonfragile_tracker.control.simulation.follow import simulate_following
    from nonfragile_tracker.control.simulation.gains import read_gain_file
    from nonfragile_tracker.control.simulation.limits import Limits, within_limits
    from nonfragile_tracker.control.simulation.plant import PlantConfig
    from nonfragile_tracker.control.simulation.tracker import TrackerConfig
    sc = yaml.safe_load((ROOT / 'config' / 'line_arc_scenario.yaml').read_text())
    pl, tp = sc['/**/plant']['ros__parameters'], sc['/**/tracker']['ros__parameters']
    K = read_gain_file(ROOT / 'config' / 'tracker_gains.yaml')
    pred = {k: tp[k] for k in ('predict_latency', 'predict_odom_latency', 'predict_lag_v',
                               'predict_lag_w')}
    lim = Limits.from_values(tp)
    out: dict = {}
    all_cases = cases()
    for k, name in enumerate(('rectangle 3 x 1.5 m, 0.05 s + goal',
                              'S backwards, 0.05 s + goal'), 1):
        traj = all_cases[name]
        cells = []
        for variant in ('plan', 'today', 'now'):
            if variant == 'plan':
                f = traj
            elif variant == 'today':
                if before is None:
                    cells.append('today -')
                    continue
                f = before.retime(traj, before.Limits(**lim.__dict__)).trajectory
            else:
                f = within_limits(traj, lim, 1.0)[0]   # the whole limits, as 'today' had
            s0 = f.sample(f.t_start)
            pc = PlantConfig(dt=pl['dt'], cmd_latency=pl['cmd_latency'], lag_v=pl['lag_v'],
                             lag_w=pl['lag_w'], max_linear_accel=pl['max_linear_accel'],
                             max_angular_accel=pl['max_angular_accel'],
                             odom_rate=pl['odom_rate'], odom_noise=(0.0, 0.0, 0.0),
                             x0=s0.x, y0=s0.y, th0=s0.heading)
            tc = TrackerConfig(K=K, dt=tp['dt'], max_linear_speed=tp['max_linear_speed'],
                               max_angular_speed=tp['max_angular_speed'], **pred)
            run = simulate_following(pc, tc, f, int(round((f.t_end + 3.0) / pc.dt)))
            act = (run.t >= f.t_start) & (run.t <= f.t_end)
            e = run.error[act]
            rms, mx = math.sqrt(float(np.mean(e * e))), float(e.max())
            out[f'{name} {variant}'] = {'duration': f.duration, 'rms': rms, 'max': mx}
            cells.append(f'{variant} {fmt(f.duration, 4)} s: {fmt(rms * 1e3)} / '
                         f'{fmt(mx * 1e3)} mm')
        now = out.get(f'{name} now', {})
        table.add(f'R.8.{k}', f'followed on issue 23\'s base, {name}: RMS (max)',
                  now.get('rms', math.nan) * 1e3, 'mm', '; '.join(cells),
                  'shipped gain, scenario predictor, no noise')
    return out


def main(argv=None) -> int:
    import argparse
    from harness import Config
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--quick', action='store_true')
    args = ap.parse_args(argv)
    table, raw = Table(), {}
    bench_retime(Config(args.quick, 120.0), table, raw)
    print(table.render())
    return 0


if __name__ == '__main__':
    sys.exit(main())
