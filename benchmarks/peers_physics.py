#!/usr/bin/env python3
"""Issue 38 on the physics bases (issue 39): ours and the stock peers on the MuJoCo bases.

    .venv/bin/python benchmarks/peers_physics.py [--bases turtlebot3,jackal,jackal_skid]
        [--latencies 0,0.1] [--seeds 1,2,3] [--jobs N] [--json PATH]

Every run goes through :func:`peers.adapter.run` with ``plant=`` the base
(``nonfragile_tracker.control.simulation.physics.PhysicsPlant``, the MJCF file of
``config/bases/``): the same base, command line (latency ``L``, +0/10 ms jitter at random),
odometry (the base's encoders at 50 Hz, plus 1 mm / 1 mrad noise), trajectory and clamps for
every controller.  The clamps are the base file's speed limits where they are below the
table's 1 m/s and 2 rad/s (the TurtleBot3 0.22 m/s and 2 rad/s; the Jackals 1 m/s and
2 rad/s): a peer's own speed settings stay stock, its output is clamped by the adapter as
every controller's is.  Trajectories: the figure eight of ``physics_bases.EIGHTS`` per base
(TurtleBot3 r 0.4 m at 0.3 rad/s, the Jackals r 1 m at 0.2 rad/s; 40 s, from 10 cm beside
it) and the line-arc lap ``config/trajectories/line_arc_lap.csv`` re-timed within the
base's limits (``physics_bases.ROBOT_LIMITS``' speeds - the TurtleBot3 0.15 m/s, where its
outer wheel stays below the motors' no-load speed in the lap's 0.4 m arcs - and the base
file's accelerations, 80 % as the tracker node does).  Controllers: ours as shipped (the shipped gain, ``monitor_tune`` on: the
tracker's default), the same with ``monitor_tune`` off, ours with the shipped gain + the predictor and gain
compensation ``physics_bases.identify`` finds on the base (:data:`OURS_IDENTIFIED`), ours
after the bring-up's chain in process (:data:`OURS_BRINGUP`: the same identification with
the acceleration limits and the side slip from the true pose, then ``latency-design``:
the designed gain with everything the gain file sets), WPILib LTV and RAMSETE, Nav2 RPP and MPPI (Jazzy, stock;
MPPI with the first seed only: 30-40 s of numpy a run).  Scored by
:func:`peers.adapter.score` on the TRUE pose (after 10 s while the trajectory is active),
and beside it the same time-indexed RMS of the odometry's pose (what the controller sees;
the encoders drift from the truth with slip).  Medians of the seeds.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
for _p in (HERE, ROOT, ROOT / 'test'):
    if str(_p) not in sys.path:
        sys.path.insert(0, str(_p))

from peers import adapter  # noqa: E402  (benchmarks/peers/, the package)
from peers_ros import peers_bench  # noqa: E402  (benchmarks/peers.py, the table's script)

BASES = ('turtlebot3', 'jackal', 'jackal_skid')
TRAJECTORIES = ('figure eight', 'line-arc lap')
#: Ours with the shipped gain told what ``physics_bases.identify`` finds on the base (20 s of
#: random steps through its odometry, at the run's latency): the predictor's latency and
#: lags and the gain compensation - issue 39's bring-up chain short of a new gain design.
OURS_IDENTIFIED = 'ours, shipped gain + identified predictor'
#: Ours after the bring-up's chain in process: ``physics_bases.identify`` (latency, lags,
#: acceleration limits, channel gains, and the side slip from the true pose) then
#: ``latency-design`` from it (``commissioning.design_gain``, the bring-up's own step): the
#: designed gain with the gain file's tracker settings.
OURS_BRINGUP = 'ours after bring-up (identified, designed)'
#: Ours as shipped (the tracker's defaults: ``monitor_tune`` on) and with the tuning off:
#: the rows of benchmarks/peers.py.
SHIPPED, UNTUNED = peers_bench.OURS_DEFAULT, peers_bench.OURS_UNTUNED
CONTROLLERS = (SHIPPED, UNTUNED, OURS_IDENTIFIED,
               OURS_BRINGUP, 'WPILib LTV',
               'WPILib RAMSETE', 'Nav2 RPP (Jazzy)', 'Nav2 MPPI (Jazzy)')
HEAVY = ('Nav2 MPPI (Jazzy)',)
PATH_FOLLOWERS = ('Nav2 RPP (Jazzy)', 'Nav2 MPPI (Jazzy)')
START = (0.0, -0.1, math.pi / 4, 0.0)
SETTLE = 10.0
NOISE = (0.001, 0.001, 0.001)
JITTER = 0.01


def clamps(base: str) -> tuple[float, float]:
    """The clamps of every controller (m/s, rad/s): the base file's speed limits where
    they are below the table's 1 m/s and 2 rad/s."""
    from nonfragile_tracker.control.simulation import physics
    from nonfragile_tracker.control.simulation.plant import PlantConfig
    spec = physics.PhysicsPlant(PlantConfig(dt=0.01), base).spec
    return min(1.0, spec.max_linear_speed), min(2.0, spec.max_angular_speed)


def base_trajectory(base: str, name: str):
    """``(trajectory, start, duration s)`` of ``name`` on ``base``."""
    from nonfragile_tracker.control.simulation import physics
    from nonfragile_tracker.control.simulation.limits import Limits, within_limits
    from nonfragile_tracker.control.simulation.plant import PlantConfig
    from nonfragile_tracker.control.simulation.reference import figure_eight
    from nonfragile_tracker.control.simulation.trajectory import Trajectory, load_waypoints
    import physics_bases
    if name == 'figure eight':
        radius, rate, _ = physics_bases.EIGHTS[base]
        return Trajectory.analytic(figure_eight(radius=radius, rate=rate)), START, 40.0
    spec = physics.PhysicsPlant(PlantConfig(dt=0.01), base).spec
    v, w = physics_bases.ROBOT_LIMITS[base]
    traj = within_limits(load_waypoints(ROOT / 'config' / 'trajectories' / 'line_arc_lap.csv'),
                         Limits(max_linear_speed=v, max_angular_speed=w,
                                max_linear_accel=spec.max_linear_accel,
                                max_angular_accel=spec.max_angular_accel))[0]
    s = traj.sample(traj.t_start)
    return traj, (s.x, s.y, s.heading, 0.0), traj.t_end + 5.0


_IDENT: dict = {}


def _identified(base: str, lat: float) -> dict:
    """``physics_bases.identify`` on ``base`` at command latency ``lat``, 50 Hz odometry."""
    if (base, lat) not in _IDENT:
        import physics_bases
        i = physics_bases.identify(base, dict(dt=0.01, cmd_latency=lat, odom_rate=50.0))
        _IDENT[(base, lat)] = {k: float(getattr(i, k)) for k in (
            'latency_s', 'tau_v_s', 'tau_w_s', 'gain_v', 'gain_w')}
    return _IDENT[(base, lat)]


_DESIGNS: dict = {}


def _designed(base: str, lat: float) -> dict:
    """The gain file's tracker section of the bring-up's chain on ``base`` at ``lat``."""
    if (base, lat) not in _DESIGNS:
        import tempfile
        import yaml
        import physics_bases
        from nonfragile_tracker.workflows.commissioning import design_gain
        ident = physics_bases.identify(base, dict(dt=0.01, cmd_latency=lat, odom_rate=50.0))
        with tempfile.TemporaryDirectory() as d:
            out = design_gain(ident, ROOT / 'config' / 'paper_problem.yaml',
                              Path(d) / 'gains.yaml')
            data = yaml.safe_load(out.gain_file.read_text())
        _DESIGNS[(base, lat)] = dict(data['/**/tracker']['ros__parameters'])
    return _DESIGNS[(base, lat)]


def one(job: tuple) -> dict:
    """One run: ``(controller, base, trajectory, latency, seed)``."""
    label, base, tname, lat, seed = job
    from nonfragile_tracker.control.simulation import physics
    from nonfragile_tracker.control.simulation.gains import read_gain_file
    from nonfragile_tracker.control.simulation.plant import PlantConfig
    from nonfragile_tracker.control.simulation.tracker import TrackerConfig
    traj, (x0, y0, th0, v0), duration = base_trajectory(base, tname)
    pc = PlantConfig(dt=0.01, x0=x0, y0=y0, th0=th0, v0=v0, cmd_latency=lat,
                     cmd_latency_jitter=JITTER, odom_rate=50.0, odom_noise=NOISE,
                     noise_seed=seed)
    vmax, wmax = clamps(base)
    base_kw = dict(peers_bench.scenario_tracker(), max_linear_speed=vmax,
                   max_angular_speed=wmax)
    if label == OURS_IDENTIFIED:
        ident = _identified(base, lat)
        base_kw.update(predict_latency=ident['latency_s'], predict_lag_v=ident['tau_v_s'],
                       predict_lag_w=ident['tau_w_s'], gain_v=ident['gain_v'],
                       gain_w=ident['gain_w'])
    if label == OURS_BRINGUP:
        from nonfragile_tracker.interface.msgconv import tracker_config_from
        values = _designed(base, lat)
        K = np.reshape(values['K'], values['K_shape'])
        tc = tracker_config_from({**values, **base_kw}, K)
    else:
        tc = TrackerConfig(K=read_gain_file(ROOT / 'config' / 'tracker_gains.yaml'), **base_kw)
    odom: list[tuple[float, float]] = []

    class Logged(physics.PhysicsPlant):
        def advance(self) -> None:
            super().advance()
            odom.append(self.odom_pose[:2])

    peers, _ = peers_bench.discover_peers()
    t0 = time.perf_counter()
    factory = adapter.OURS if label in (OURS_IDENTIFIED, OURS_BRINGUP) else \
        peers_bench._factory(label, peers)
    pr = adapter.run(factory, pc, tc, traj, duration,
                     plant=lambda c: Logged(c, base))
    wall = time.perf_counter() - t0
    s = adapter.score(pr, SETTLE)
    r = pr.run
    o = np.array([(x0, y0)] + odom)[:len(r.t)]
    t_end = min(traj.t_end, r.t[-1]) if math.isfinite(traj.t_end) else r.t[-1]
    win = (r.t >= SETTLE) & (r.t <= t_end)
    seen = np.hypot(o[win, 0] - r.xd[win], o[win, 1] - r.yd[win])
    drift = math.hypot(o[-1, 0] - r.x[-1], o[-1, 1] - r.y[-1])
    return {'controller': label, 'base': base, 'trajectory': tname, 'latency': lat,
            'seed': seed, **s.__dict__, 'identified': _IDENT.get((base, lat)), 'odom_rms': float(np.sqrt(np.mean(seen ** 2))),
            'drift': drift, 'wall_s': wall, 'clamps': (vmax, wmax)}


def _mm(x: float) -> str:
    if not math.isfinite(x):
        return 'nan'
    x *= 1e3
    return f'{x:.3g}' if x < 100 else f'{x:.0f}'


def render(results: list[dict], bases, trajs, lats) -> str:
    cells: dict = {}
    for r in results:
        cells.setdefault((r['controller'], r['base'], r['trajectory'], r['latency']), []).append(r)
    out = []
    for base in bases:
        v, w = clamps(base)
        for tn in trajs:
            out.append(f'\n#### {base}, {tn} (clamps {v:g} m/s, {w:g} rad/s)\n')
            out.append('| controller | ' + ' | '.join(
                f'{lat * 1e3:g} ms: true RMS (max) / odom-frame RMS / cross-track RMS'
                for lat in lats) + ' |')
            out.append('|---' * (1 + len(lats)) + '|')
            for c in CONTROLLERS:
                row = []
                for lat in lats:
                    rs = cells.get((c, base, tn, lat))
                    if not rs:
                        row.append('-')
                        continue
                    med = {k: statistics.median(r[k] for r in rs)
                           for k in ('rms', 'max', 'odom_rms', 'cross_rms')}
                    div = 0 if c in PATH_FOLLOWERS else sum(r['diverged'] for r in rs)
                    row.append(f'{"**div %d/%d** " % (div, len(rs)) if div else ""}'
                               f'{_mm(med["rms"])} ({_mm(med["max"])}) / {_mm(med["odom_rms"])}'
                               f' / {_mm(med["cross_rms"])}' + (f' [n={len(rs)}]'
                                                                if len(rs) == 1 else ''))
                out.append(f'| {c} | ' + ' | '.join(row) + ' |')
    return '\n'.join(out) + '\n'


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--bases', default=','.join(BASES))
    ap.add_argument('--trajectories', default=','.join(TRAJECTORIES))
    ap.add_argument('--latencies', default='0,0.1')
    ap.add_argument('--seeds', default='1,2,3')
    ap.add_argument('--controllers', default=';'.join(CONTROLLERS),
                    help='labels separated by ";" (labels hold commas)')
    ap.add_argument('--jobs', type=int, default=0, help='worker processes (default: CPUs)')
    ap.add_argument('--json', help='every run\'s figures as JSON')
    ap.add_argument('--from-json', help='render only: the runs of earlier --json files '
                    '(comma list), merged')
    args = ap.parse_args(argv)
    bases = args.bases.split(',')
    trajs = args.trajectories.split(',')
    lats = [float(x) for x in args.latencies.split(',')]
    seeds = [int(x) for x in args.seeds.split(',')]
    ctrls = [c for c in CONTROLLERS if c in args.controllers.split(';')]
    todo = [(c, b, tn, lat, s) for c in ctrls for b in bases for tn in trajs for lat in lats
            for s in seeds if not (c in HEAVY and s != seeds[0])]
    todo.sort(key=lambda j: j[0] not in HEAVY)
    if args.from_json:
        results = [r for f in args.from_json.split(',') for r in json.loads(Path(f).read_text())]
        print(render(results, bases, trajs, lats))
        print(f'({len(results)} runs from {args.from_json})')
        return 0
    t0 = time.perf_counter()
    if OURS_BRINGUP in ctrls:                 # designed once here, inherited by the workers
        for b in bases:
            for lat in lats:
                print(f'bring-up chain: {b} at {lat * 1e3:g} ms', file=sys.stderr, flush=True)
                _designed(b, lat)
    print(f'{len(todo)} runs', file=sys.stderr, flush=True)
    jobs = args.jobs or os.cpu_count() or 1
    if jobs > 1:
        with ProcessPoolExecutor(jobs) as ex:
            results = list(ex.map(one, todo))
    else:
        results = [one(j) for j in todo]
    print(f'Ours and the stock peers on the physics bases: time-indexed RMS (max) after '
          f'{SETTLE:g} s of the TRUE pose / the same of the odometry frame / cross-track RMS '
          f'of the true pose, mm; command latency +0/10 ms jitter, 50 Hz odometry with 1 mm '
          f'noise; median of seeds {args.seeds} (MPPI: the first seed, [n=1]); path '
          f'followers (RPP, MPPI) drive at their own speed: their timed error is not their '
          f'measure, the cross-track is (no divergence mark).')
    print(render(results, bases, trajs, lats))
    print(f'({len(results)} runs, {time.perf_counter() - t0:.0f} s wall on {jobs} workers)')
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=1, default=str))
    return 0


if __name__ == '__main__':
    sys.exit(main())
