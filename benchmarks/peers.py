#!/usr/bin/env python3
"""Issue 38: our tracker beside the trackers users run, on the same bases, side by side.

    .venv/bin/python benchmarks/peers.py [--quick] [--jobs N] [--out benchmarks/peers_table.md]
        [--plot doc/images/peers_latency.png] [--json PATH] [--controllers LABEL,...]
    .venv/bin/python benchmarks/peers.py --ablation     # our default's gap: gain or predictor

Controllers (rows): ours with ``monitor_tune`` off (``config/tracker_gains.yaml`` with the
tracker settings of ``config/paper_scenario.yaml``, as ``make demo`` / ``run`` loads them: no
predictor, the base's acceleration limits unknown), ours as shipped (the same with the
tracker's default online tuning, ``monitor_tune`` on: its predictor follows the latency and
lags it measures, as the node's does), ours after the bring-up (what ``bringup`` configures
for the base with an exact identification: predictor at the true command latency, the true
lags, the acceleration limits, and a gain from ``latency-design`` for the residual delay
the bring-up certifies, ``[0, jitter + odometry period]`` with the 50 ms lag - designs
cached in ``benchmarks/results/peers_designs.json``), ours after the bring-up as a user runs
it (:func:`identified_bringup`: record with the shipped gain, ``identify``,
``latency-design --identification``; cached in ``benchmarks/results/peers_bringup/``), then
every peer of ``benchmarks/peers/`` (each module's ``PEERS``; WPILib's LTV, LTV with
WPILib's latency compensation, RAMSETE; Nav2's when their modules are there).  A module that
cannot be imported is listed as skipped with the reason.

Columns: command latency 0 / 40 / 100 / 200 / 300 ms x trajectories (figure eight r = 1 m
at 0.2 rad/s from 10 cm beside it; the line-arc lap ``config/trajectories/line_arc_lap.csv``;
a rounded rectangle 3 x 1.5 m sampled every 50 ms as a planner logs it; an S with 2 m
straights driven backwards, the same way: ``test/planner_files.py``) x odometry 50 Hz and
20 Hz, on the package's realistic plant (:data:`peers.adapter.REALISTIC`: 50 ms lag on v
and w, 1 m/s^2 and 3 rad/s^2, 1 mm / 1 mrad odometry noise, command latency jittered by one
10 ms step), 3 noise seeds, medians.  The timed trajectories are re-timed within the base's limits
(80 % of its accelerations, as the tracker node does) once, and every controller gets the
same re-timed one.  Every run goes through :func:`peers.adapter.run` (same plant,
odometry, loop, clamps |v| <= 1 m/s, |w| <= 2 rad/s).

Figures (:func:`peers.adapter.score`, after 10 s while the trajectory is active): RMS and max
of the time-indexed error |p - p_d(t)| (true pose), RMS and max cross-track error (distance
to the planned path), arrival at the end against the plan (s; the timed trajectories),
RMS dw/dt of the commands, share of commands at a speed limit, diverged (time-indexed error
above 0.25 m: k of 3 seeds), compute per command (the controller's step alone, median and
99th percentile over the run, us).  ``--quick``: 50 Hz only, the figure eight (30 s) and
the line-arc lap, every controller at every latency, 3 seeds, but MPPI (30-40 s of numpy a
run) stock only, at 100 ms, one seed; on one worker per CPU (``--jobs``' default) it takes
under 3 minutes on two cores; it prints the tables and writes nothing unless
``--out``/``--plot`` are given.
"""
from __future__ import annotations

import argparse
import hashlib
import importlib
import json
import math
import re
import pkgutil
import statistics
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
for _p in (HERE, ROOT, ROOT / 'test'):
    if str(_p) not in sys.path:
        sys.path.insert(0, str(_p))

import peers as peer_pkg  # noqa: E402  (benchmarks/peers/, the package: it wins over this file)
from peers import adapter  # noqa: E402

CONFIG = ROOT / 'config'
LATENCIES = (0.0, 0.04, 0.1, 0.2, 0.3)
RATES = (50.0, 20.0)
SEEDS = (1, 2, 3)
SETTLE = 10.0
#: The base's limits: the trajectories are re-timed within them (and the bring-up knows them).
BASE_LIMITS = dict(max_linear_speed=1.0, max_linear_accel=1.0, max_angular_speed=2.0,
                   max_angular_accel=3.0)
#: Ours as shipped: the shipped gain with the tracker's defaults, the online tuning
#: (``monitor_tune``, on by default) included: it measures the base's latency and lags from
#: its own commands and odometry and predicts them.
OURS_DEFAULT = 'ours as shipped (monitor_tune on)'
#: The same with the tuning turned off (``monitor_tune: false``; the default until 2026-12):
#: the law alone, no predictor, for comparison.
OURS_UNTUNED = 'ours, shipped gain, monitor_tune off'
OURS_BRINGUP = 'ours after bring-up'
OURS_IDENTIFIED = 'ours after bring-up (identified)'
OURS = (OURS_UNTUNED, OURS_DEFAULT, OURS_BRINGUP, OURS_IDENTIFIED)
#: Our rows that know nothing of the base (judged against the stock peers from 40 ms).
OURS_UNTOLD = (OURS_UNTUNED, OURS_DEFAULT)
#: Peers a module lists in ``HEAVY`` (seconds per run: MPPI's 2000 x 56 rollouts in numpy)
#: run these latencies with the first seed only; in --quick only as stock (their
#: ``VARIANTS`` are left to the full table) and at :data:`HEAVY_QUICK_LATENCIES`.
QUICK_HEAVY_LATENCIES = (0.0, 0.1, 0.3)
#: --quick: the heavy peers' one latency (each run is 30-40 s of numpy; the whole --quick
#: must stay under 3 minutes on two cores).
HEAVY_QUICK_LATENCIES = (0.1,)
TRAJECTORIES = ('figure eight', 'line-arc lap', 'rounded rectangle', 'backwards S')
DESIGN_CACHE = HERE / 'results' / 'peers_designs.json'
BRINGUP_DIR = HERE / 'results' / 'peers_bringup'


# ------------------------------------------------------------------------- trajectories

def trajectory(name: str, quick: bool = False):
    """``(trajectory, start (x, y, th, v), duration s, settle s)`` of a named trajectory.

    All are scored after :data:`SETTLE` (the figure eight starts 10 cm beside the path; the
    timed trajectories start at the robot, at rest, and last about 22 s: their first seconds,
    the departure the latency delays, are in the "while active" figures).  The S has 2 m
    straights so that it lasts as long as the others.
    """
    from nonfragile_tracker.control.simulation.limits import Limits, within_limits
    from nonfragile_tracker.control.simulation.reference import figure_eight
    from nonfragile_tracker.control.simulation.trajectory import (Trajectory, from_waypoints,
                                                                  load_waypoints)
    if name == 'figure eight':
        # benchmarks/latency.py's start beside the path (10 cm off, at rest)
        return (Trajectory.analytic(figure_eight(radius=1.0, rate=0.2)),
                (0.0, -0.1, math.pi / 4, 0.0), 30.0 if quick else 40.0, SETTLE)
    if name == 'line-arc lap':
        traj = load_waypoints(CONFIG / 'trajectories' / 'line_arc_lap.csv')
    else:
        import planner_files as pf
        rows = (pf.sample(pf.rounded_rectangle()) if name == 'rounded rectangle' else
                pf.sample(pf.s_curve(straight=2.0), speed=0.3, backwards=True))
        traj = from_waypoints(rows['t'], rows['x'], rows['y'], yaw=rows['yaw'],
                              speed=rows['speed'], source=name)
    traj = within_limits(traj, Limits(**BASE_LIMITS))[0]
    s = traj.sample(traj.t_start)
    return traj, (s.x, s.y, s.heading, 0.0), traj.t_end + 5.0, SETTLE


# ------------------------------------------------------------------------- controllers

def scenario_tracker() -> dict:
    """The shipped scenario's tracker settings ``make demo`` runs with (speeds, min_speed)."""
    from nonfragile_tracker.interface.scenario import node_parameters
    p = node_parameters('tracker')
    return {k: float(p[k]) for k in ('max_linear_speed', 'max_angular_speed', 'min_speed')}


def residual_interval(pc) -> tuple[float, float]:
    """The delay the bring-up certifies with the predictor (latency-design's one rule):
    ``[0, (latency range) + (odometry age range) + command period]``."""
    from nonfragile_tracker.control.simulation.plant import odometry_period_steps
    from nonfragile_tracker.control.synthesis.latency_design import delay_interval
    n, _ = odometry_period_steps(pc.odom_rate, pc.dt)
    lo, hi = pc.cmd_latency, pc.cmd_latency + pc.cmd_latency_jitter
    return delay_interval(lo, hi, predictor=True, command_period=n * pc.dt)


def _problem_file() -> Path:
    return CONFIG / 'paper_problem.yaml'


def design_gain(h0: float, h1: float, lag: float) -> tuple[list, dict]:
    """``latency-design`` for ``[h0, h1]`` s and ``lag`` on the paper problem, cached on disk.

    Returns ``(K as nested lists, figures)``; the cache key holds the interval, the lag and
    the problem file's hash.
    """
    key = (f'{h0:.4f},{h1:.4f},{lag:.4f},'
           f'{hashlib.sha256(_problem_file().read_bytes()).hexdigest()[:12]}')
    cache = json.loads(DESIGN_CACHE.read_text()) if DESIGN_CACHE.exists() else {}
    if key in cache:
        return cache[key]['K'], cache[key]['figures']
    from nonfragile_tracker.control.synthesis.latency_design import design_for_latency
    from nonfragile_tracker.control.synthesis.problem import load_problem
    t = time.perf_counter()
    d = design_for_latency(load_problem(_problem_file()), h0, h1, lag=lag)
    figures = {'decay_rate': d.decay_rate, 'lag_certified_h_max': d.lag_certified_h_max,
               'gain_norm': float(__import__('numpy').linalg.norm(d.K, 2)),
               'design_s': time.perf_counter() - t}
    cache[key] = {'K': d.K.tolist(), 'figures': figures}
    DESIGN_CACHE.parent.mkdir(parents=True, exist_ok=True)
    DESIGN_CACHE.write_text(json.dumps(cache, indent=1))
    return cache[key]['K'], figures


def our_config(label: str, pc):
    """The tracker config of one of our two rows on the base ``pc``."""
    from nonfragile_tracker.control.simulation.gains import read_gain_file
    from nonfragile_tracker.control.simulation.tracker import TrackerConfig
    base = scenario_tracker()
    if label in OURS_UNTOLD:
        return TrackerConfig(K=read_gain_file(CONFIG / 'tracker_gains.yaml'), **base)
    if label == OURS_IDENTIFIED:
        return TrackerConfig(**identified_bringup(pc), **base)
    h0, h1 = residual_interval(pc)
    K, _ = design_gain(h0, h1, max(pc.lag_v, pc.lag_w))
    return TrackerConfig(K=K, predict_latency=pc.cmd_latency, predict_lag_v=pc.lag_v,
                         predict_lag_w=pc.lag_w, max_linear_accel=pc.max_linear_accel,
                         max_angular_accel=pc.max_angular_accel, **base)


def _bringup_key(pc) -> str:
    digest = hashlib.sha256(_problem_file().read_bytes() + (CONFIG / 'tracker_gains.yaml')
                            .read_bytes()).hexdigest()[:10]
    return (f'L{pc.cmd_latency:.3f}_J{pc.cmd_latency_jitter:.3f}_R{pc.odom_rate:g}_'
            f'lag{pc.lag_v:.3f}-{pc.lag_w:.3f}_acc{pc.max_linear_accel:g}-'
            f'{pc.max_angular_accel:g}_{digest}')


def identified_bringup(pc) -> dict:
    """The tracker settings of the bring-up as a user runs it on the base ``pc``, cached.

    benchmarks/latency.py's in-process chain (``--real-base``, part 2): record 30 s of the
    figure eight (r = 1 m, 0.2 rad/s, from 10 cm beside it) with the shipped gain, no
    predictor and the base's acceleration limits set, on this base (seed 1); ``identify``
    the commands and odometry; ``latency-design config/paper_problem.yaml --identification``
    (the CLI, in process).  Returns ``K``, the ``predict_*`` parameters the gain file sets
    and the acceleration limits (the identified ones, else the base's, as the bring-up's
    robot file keeps them).  Cached under ``benchmarks/results/peers_bringup/``.
    """
    import latency as latency_bench
    from nonfragile_tracker.control.identification.identify import (CommandSamples,
                                                                    OdometrySamples)
    from nonfragile_tracker.control.simulation.gains import read_gain_file
    from nonfragile_tracker.control.simulation.tracker import Tracker, TrackerConfig
    from nonfragile_tracker.control.simulation.timing import step_time
    from nonfragile_tracker.control.simulation.reference import figure_eight
    from nonfragile_tracker.control.simulation.simulate import run_loop
    d = BRINGUP_DIR / _bringup_key(pc)
    gains = d / 'g.yaml'
    if not gains.exists():
        d.mkdir(parents=True, exist_ok=True)
        rec = adapter.base_plant(pc.cmd_latency, pc.odom_rate, 1, (0.0, -0.1, math.pi / 4, 0.0),
                                 lag_v=pc.lag_v, lag_w=pc.lag_w,
                                 max_linear_accel=pc.max_linear_accel,
                                 max_angular_accel=pc.max_angular_accel,
                                 cmd_latency_jitter=pc.cmd_latency_jitter)
        tr = Tracker(TrackerConfig(K=read_gain_file(CONFIG / 'tracker_gains.yaml'),
                                   max_linear_accel=pc.max_linear_accel,
                                   max_angular_accel=pc.max_angular_accel,
                                   **scenario_tracker()))
        path = figure_eight(radius=1.0, rate=0.2)
        cmds, odom = [], []

        def command(meas, th, k, ref):
            ts = step_time(meas.step, rec.dt)
            cmd = tr.step(meas.x, meas.y, th, path.sample(ts), meas.v, stamp=ts)
            cmds.append((step_time(k, rec.dt), cmd.v, cmd.w))
            odom.append((ts, meas.x, meas.y, th, meas.v, meas.w))
            return cmd

        run_loop(rec, int(round(30.0 / rec.dt)), command,
                 lambda k: path.sample(step_time(k, rec.dt)))
        c, o = __import__('numpy').array(cmds).T, __import__('numpy').array(odom).T
        ident = latency_bench.identify_file(CommandSamples(*c), OdometrySamples(*o),
                                            d / 'latency.yaml', f'peers bring-up {d.name}')
        latency_bench.design_from(ident, gains)
    sec = latency_bench.tracker_section(gains)
    out = {'K': read_gain_file(gains).tolist()}
    out.update({k: float(v) for k, v in sec.items() if k.startswith('predict_')})
    for k in ('max_linear_accel', 'max_angular_accel'):
        out[k] = float(sec.get(k) or getattr(pc, k))
    return out


def discover_peers() -> tuple[dict, dict]:
    """``({label: (module, attribute)}, {module: why skipped})`` of ``benchmarks/peers/``."""
    found: dict = {}
    skipped: dict = {}
    for info in sorted(pkgutil.iter_modules(peer_pkg.__path__), key=lambda m: m.name):
        if info.name == 'adapter' or info.name.startswith('_'):
            continue
        try:
            mod = importlib.import_module(f'peers.{info.name}')
        except Exception as exc:          # noqa: BLE001 - a peer's library missing: say so
            skipped[info.name] = f'import failed: {exc!r}'[:200]
            continue
        table = getattr(mod, 'PEERS', None)
        if not isinstance(table, dict) or not table:
            skipped[info.name] = 'no PEERS dict (label -> factory)'
            continue
        for label, f in table.items():
            if callable(f):
                found[str(label)] = (f'peers.{info.name}', label)
    return found, skipped


def _tuned_factory():
    """Our law wrapped as the tracker node wraps it by default (``monitor_tune`` on; the
    shipped gain file's monitor parameters, the scenario's speeds): the input rules' tuning."""
    from nonfragile_tracker.control.identification.tuning import Tuned
    from nonfragile_tracker.control.simulation.tracker import Tracker
    from nonfragile_tracker.interface.scenario import node_parameters
    from nonfragile_tracker.interface.tracker_inputs import input_rules
    values = dict(node_parameters('tracker'))
    values.update(node_parameters('tracker', CONFIG / 'tracker_gains.yaml'))
    tune = input_rules(values).tune
    assert tune is not None, 'the shipped defaults no longer tune: relabel the rows'

    def make(config):
        return Tuned(Tracker(config), *tune)
    return make


def _factory(label: str, peers: dict):
    if label == OURS_DEFAULT:
        return _tuned_factory()
    if label in OURS:
        return adapter.OURS
    mod, key = peers[label]
    return importlib.import_module(mod).PEERS[key]


# ------------------------------------------------------------------------- the runs

def one(job: tuple) -> dict:
    """One run (a worker's unit): ``(label, trajectory, latency, rate, seed, quick)``."""
    label, tname, lat, rate, seed, quick = job
    peers, _ = discover_peers()
    traj, start, duration, settle = _trajectory_cached(tname, quick)
    pc = adapter.base_plant(lat, rate, seed, start)
    if label in OURS:
        tc = our_config(label, pc)
    else:
        from nonfragile_tracker.control.simulation.gains import read_gain_file
        from nonfragile_tracker.control.simulation.tracker import TrackerConfig
        # a peer reads only the speed limits (the clamps) of the tracker config
        tc = TrackerConfig(K=read_gain_file(CONFIG / 'tracker_gains.yaml'),
                           **scenario_tracker())
    pr = adapter.run(_factory(label, peers), pc, tc, traj, duration)
    s = adapter.score(pr, settle)
    return {'controller': label, 'trajectory': tname, 'latency': lat, 'rate': rate,
            'seed': seed, **s.__dict__}


_TRAJ: dict = {}


def _trajectory_cached(name: str, quick: bool):
    if (name, quick) not in _TRAJ:
        _TRAJ[(name, quick)] = trajectory(name, quick)
    return _TRAJ[(name, quick)]


FIGS = ('rms', 'max', 'rms_active', 'max_active', 'cross_rms', 'cross_max', 'lap_delta',
        'dw_rms', 'saturated', 'compute_med_us', 'compute_p99_us')


def medians(results: list[dict]) -> dict:
    """``{(controller, trajectory, rate, latency): {figure: median over seeds, 'div': k}}``."""
    cells: dict = {}
    for r in results:
        cells.setdefault((r['controller'], r['trajectory'], r['rate'], r['latency']), []).append(r)
    out = {}
    for key, rs in cells.items():
        m = {}
        for f in FIGS:
            vals = [r[f] for r in rs if r[f] is not None and math.isfinite(r[f])]
            m[f] = statistics.median(vals) if vals else math.nan
        m['div'] = sum(bool(r['diverged']) for r in rs)
        m['n'] = len(rs)
        out[key] = m
    return out


def _mm(x: float) -> str:
    if not math.isfinite(x):
        return '-'
    x *= 1e3
    return f'{x:.2f}' if x < 10 else (f'{x:.1f}' if x < 100 else f'{x:.0f}')


def _cell(m: dict | None) -> str:
    if m is None:
        return ''
    s = f"{_mm(m['rms'])} ({_mm(m['max'])})"
    if m['div']:
        s = f"**div {m['div']}/{m['n']}** " + s
    return s


def render(med: dict, controllers: list[str], trajs: list[str], rates: list[float],
           lats: list[float], followers: tuple[str, ...] = ()) -> str:
    """The markdown tables: a summary per trajectory and rate, then every figure.

    The timed trackers' summary is the time-indexed error; the path followers
    (``followers``: they drive the path at their own speed, so the timed error only says how
    far behind the clock they are) get a cross-track summary beside everyone's.
    """
    out = []
    timed = [c for c in controllers if c not in followers]
    for tname in trajs:
        for rate in rates:
            out.append(f'\n### {tname}, odometry {rate:g} Hz: time-indexed RMS (max) after '
                       f'{SETTLE:g} s, mm\n')
            out.append('| controller | ' + ' | '.join(f'{lat * 1e3:g} ms' for lat in lats)
                       + ' |')
            out.append('|---' * (len(lats) + 1) + '|')
            best = {}
            for lat in lats:
                vals = [(med[(c, tname, rate, lat)]['rms'], c) for c in controllers
                        if (c, tname, rate, lat) in med
                        and math.isfinite(med[(c, tname, rate, lat)]['rms'])]
                best[lat] = min(vals)[1] if vals else None
            for c in timed:
                cells = []
                for lat in lats:
                    m = med.get((c, tname, rate, lat))
                    txt = _cell(m)
                    cells.append(f'**{txt}**' if best[lat] == c and not (m and m['div'])
                                 else txt)
                out.append(f'| {c} | ' + ' | '.join(cells) + ' |')
            if not followers:
                continue
            out.append(f'\n{tname}, {rate:g} Hz: cross-track RMS (max) after {SETTLE:g} s, mm '
                       '(path followers judged here; the timed trackers beside them)\n')
            out.append('| controller | ' + ' | '.join(f'{lat * 1e3:g} ms' for lat in lats)
                       + ' |')
            out.append('|---' * (len(lats) + 1) + '|')
            for c in controllers:
                cells = []
                for lat in lats:
                    m = med.get((c, tname, rate, lat))
                    cells.append('' if m is None else
                                 f"{_mm(m['cross_rms'])} ({_mm(m['cross_max'])})")
                out.append(f'| {c} | ' + ' | '.join(cells) + ' |')
    out.append('\n## Every figure (medians of the seeds)\n')
    out.append(f'RMS / max: time-indexed error after {SETTLE:g} s (mm); active: the same over '
               'the whole trajectory (its departure included; the figure eight: the whole '
               'run); cross: cross-track RMS / max (mm); end: arrival at the end minus the '
               'planned end (s; - for the endless figure eight or no arrival within 2 cm); '
               'dw/dt: RMS of the commands\' yaw-rate change (rad/s^2); sat: share of commands '
               'at a speed limit (%); div: seeds diverged; compute: the controller\'s step, '
               'median / p99 (us).\n')
    for tname in trajs:
        for rate in rates:
            out.append(f'\n### {tname}, {rate:g} Hz\n')
            out.append('| controller | latency ms | RMS | max | active RMS / max | cross RMS '
                       '| cross max | end s | dw/dt | sat % | div | compute us |')
            out.append('|---' * 12 + '|')
            for c in controllers:
                for lat in lats:
                    m = med.get((c, tname, rate, lat))
                    if m is None:
                        continue
                    end = '-' if not math.isfinite(m['lap_delta']) else f"{m['lap_delta']:+.2f}"
                    out.append(
                        f"| {c} | {lat * 1e3:g} | {_mm(m['rms'])} | {_mm(m['max'])} | "
                        f"{_mm(m['rms_active'])} / {_mm(m['max_active'])} | "
                        f"{_mm(m['cross_rms'])} | {_mm(m['cross_max'])} | {end} | "
                        f"{m['dw_rms']:.2f} | {100 * m['saturated']:.1f} | {m['div']}/{m['n']} | "
                        f"{m['compute_med_us']:.0f} / {m['compute_p99_us']:.0f} |")
    return '\n'.join(out) + '\n'


def plot(med: dict, controllers: list[str], trajs: list[str], rates: list[float],
         lats: list[float], path: Path) -> None:
    """Time-indexed RMS against latency per controller (log scale), one panel per trajectory."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    n = len(trajs)
    cols = 2 if n > 1 else 1
    rows = (n + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(6.2 * cols, 4.2 * rows), squeeze=False)
    colors = plt.rcParams['axes.prop_cycle'].by_key()['color']
    if len(controllers) > len(colors):          # a colour of its own for every controller
        colors = [plt.get_cmap('tab20')(i) for i in range(20)]
    markers = 'os^Dv<>phX*P'
    for ax, tname in zip(axes.flat, trajs):
        for i, c in enumerate(controllers):
            for rate, style in zip(rates, ('-', '--')):
                ys = [med.get((c, tname, rate, lat), {}).get('rms', math.nan) * 1e3
                      for lat in lats]
                ax.plot([lat * 1e3 for lat in lats], ys, style, marker=markers[i % len(markers)],
                        ms=3.5, color=colors[i % len(colors)],
                        label=f'{c}' if rate == rates[0] else None)
        ax.axhline(adapter.DIVERGED * 1e3, color='0.6', lw=0.8, ls=':')
        ax.set_yscale('log')
        ax.set_title(tname)
        ax.set_xlabel('command latency (ms)')
        ax.set_ylabel('RMS position error (mm)')
        ax.grid(True, which='both', alpha=0.3)
    for ax in list(axes.flat)[n:]:
        ax.axis('off')
    handles, labels = axes.flat[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc='lower center', ncol=min(len(labels), 4), fontsize=8)
    styles = ', '.join(f'{r:g} Hz {s}' for r, s in zip(rates, ('solid', 'dashed')))
    fig.suptitle(f'Ours and the peers on the realistic base (median of {len(SEEDS)} seeds; '
                 f'odometry {styles}; dotted: {adapter.DIVERGED * 1e3:g} mm = diverged)',
                 fontsize=9)
    fig.tight_layout(rect=(0, 0.03 + 0.025 * ((len(controllers) - 1) // 4), 1, 1))
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def read_table(path: Path) -> dict:
    """The RMS medians of a written table (its per-run sections ``### <trajectory>, <rate>
    Hz``), as :func:`plot` takes them: ``med``, ``controllers``, ``trajs``, ``rates``, ``lats``
    in the table's order."""
    med: dict = {}
    controllers: list[str] = []
    trajs: list[str] = []
    rates: list[float] = []
    lats: list[float] = []
    section = None
    for line in Path(path).read_text().splitlines():
        head = re.fullmatch(r'### (.+), ([\d.]+) Hz', line)
        if head:
            section = (head.group(1), float(head.group(2)))
            for seen, x in ((trajs, section[0]), (rates, section[1])):
                if x not in seen:
                    seen.append(x)
            continue
        if line.startswith('#'):
            section = None
        cells = [c.strip() for c in line.strip('|').split('|')]
        if section is None or len(cells) < 3 or not re.fullmatch(r'[\d.]+', cells[1]):
            continue
        c, lat, rms = cells[0], float(cells[1]) * 1e-3, cells[2]
        controllers += [c] if c not in controllers else []
        lats += [lat] if lat not in lats else []
        med[(c, section[0], section[1], lat)] = {
            'rms': float(rms) * 1e-3 if re.fullmatch(r'[\d.]+', rms) else math.nan}
    if not med:
        raise SystemExit(f'{path}: no per-run sections ("### <trajectory>, <rate> Hz")')
    return {'med': med, 'controllers': controllers, 'trajs': trajs, 'rates': rates,
            'lats': sorted(lats)}


def run_table(quick: bool = False, jobs: int = 1, only: str = '', log=print) -> dict:
    """Every run of the table (``quick``: 50 Hz, two trajectories) and their medians.

    Returns a dict: ``results`` (one per run), ``med`` (:func:`medians`), ``controllers``,
    ``stock`` (the peers as their library ships them: not in their module's ``VARIANTS``),
    ``trajs``, ``rates``, ``lats``, ``skipped``, ``designs`` and ``wall`` (s).
    """
    t0 = time.perf_counter()
    peers, skipped = discover_peers()
    controllers = list(OURS) + list(peers)
    if only:
        want = [c.strip() for c in only.split(',') if c.strip()]
        controllers = [c for c in controllers if c in want]
    stock = [c for c in peers if c in controllers and c not in _variants(peers[c][0])]
    trajs = list(TRAJECTORIES[:2] if quick else TRAJECTORIES)
    rates = [50.0] if quick else list(RATES)
    lats = list(LATENCIES)
    designs = {}
    # the bring-up designs first (cached), so that no worker synthesises
    for rate in rates:
        pc = adapter.base_plant(0.0, rate, 1)
        h0, h1 = residual_interval(pc)
        K, fig = design_gain(h0, h1, max(pc.lag_v, pc.lag_w))
        designs[rate] = {'h': [h0, h1], 'lag': max(pc.lag_v, pc.lag_w), **fig}
        log(f'bring-up design for {rate:g} Hz: residual [{h0:.3f}, {h1:.3f}] s, lag '
            f'{max(pc.lag_v, pc.lag_w):.3f} s: decay {fig["decay_rate"]:.3g} 1/s, '
            f'||K|| {fig["gain_norm"]:.3g} (designed in {fig["design_s"]:.1f} s, cached)')
    if OURS_IDENTIFIED in controllers:       # the recorded bring-ups first (cached)
        t1 = time.perf_counter()
        for rate in rates:
            for lat in lats:
                s = identified_bringup(adapter.base_plant(lat, rate, 1))
                designs[f'{rate:g} Hz, {lat * 1e3:g} ms'] = s
                log(f'bring-up as run, {rate:g} Hz, {lat * 1e3:g} ms: predict_latency '
                    f'{s.get("predict_latency", 0.0) * 1e3:.1f} ms, lags '
                    f'{s.get("predict_lag_v", 0.0) * 1e3:.0f}/'
                    f'{s.get("predict_lag_w", 0.0) * 1e3:.0f} ms')
        log(f'bring-ups: {time.perf_counter() - t1:.0f} s (cached in {BRINGUP_DIR})')
    for name, why in skipped.items():
        log(f'peer module {name} skipped: {why}')
    heavy = {c for c in peers if c in controllers and c in _listed(peers[c][0], 'HEAVY')}
    heavy_lats = HEAVY_QUICK_LATENCIES if quick else QUICK_HEAVY_LATENCIES
    todo = [(c, tn, lat, rate, seed, quick) for tn in trajs for rate in rates
            for lat in lats for c in controllers for seed in SEEDS
            if not (c in heavy and (lat not in heavy_lats or seed != SEEDS[0]
                                    or (quick and c not in stock)))]
    # the heavy runs first: the workers' last jobs are then short ones (no lone long tail)
    todo.sort(key=lambda j: j[0] not in heavy)
    log(f'{len(todo)} runs: {len(controllers)} controllers x {len(trajs)} trajectories x '
        f'{len(rates)} rates x {len(lats)} latencies x {len(SEEDS)} seeds')
    if jobs > 1:
        with ProcessPoolExecutor(jobs) as ex:
            results = list(ex.map(one, todo, chunksize=2))
    else:
        results = [one(j) for j in todo]
    followers = [c for c in peers if c in controllers
                 and c in _listed(peers[c][0], 'PATH_FOLLOWERS')]
    return {'results': results, 'med': medians(results), 'controllers': controllers,
            'stock': stock, 'followers': followers, 'trajs': trajs, 'rates': rates,
            'lats': lats, 'skipped': skipped, 'designs': designs,
            'wall': time.perf_counter() - t0}


def _listed(module: str, name: str) -> set:
    """The labels a peer module lists under ``name`` (``VARIANTS``, ``HEAVY``, ...)."""
    return set(getattr(importlib.import_module(module), name, ()))


def _variants(module: str) -> set:
    return _listed(module, 'VARIANTS')


def ahead(t: dict) -> dict:
    """Issue 38's "ahead on every row", cell by cell (trajectory, rate, latency).

    ``bringup`` / ``identified``: ours after bring-up over the best peer (<= 1: ahead), worst
    cell; ``default`` / ``untuned``: ours with the shipped gain (as shipped, ``monitor_tune``
    on, and with it off) over the best stock peer, latencies from 40 ms.  A timed tracker is
    compared on the time-indexed RMS; a path follower (its module's ``PATH_FOLLOWERS``: it
    drives at its own speed, so the timed error says nothing of it) on the cross-track RMS,
    ours' against its.  Each entry has the cells where ours is behind.
    """
    med = t['med']
    peers = [c for c in t['controllers'] if c not in OURS]
    followers = set(t.get('followers', ()))
    out = {}
    from40 = [x for x in t['lats'] if x >= 0.04]
    for key, ours, rivals, lats in (
            ('bringup', OURS_BRINGUP, peers, t['lats']),
            ('identified', OURS_IDENTIFIED, peers, t['lats']),
            ('untuned', OURS_UNTUNED, t['stock'], from40),
            ('default', OURS_DEFAULT, t['stock'], from40)):
        worst, behind, cells = 0.0, [], 0
        for tn in t['trajs']:
            for rate in t['rates']:
                for lat in lats:
                    m = med.get((ours, tn, rate, lat))
                    if m is None:
                        continue
                    for c in rivals:
                        p = med.get((c, tn, rate, lat))
                        fig = 'cross_rms' if c in followers else 'rms'
                        if p is None or not math.isfinite(p[fig]) or p[fig] <= 0:
                            continue
                        cells += 1
                        r = m[fig] / p[fig]
                        worst = max(worst, r)
                        if r > 1.0:
                            what = 'cross-track ' if fig == 'cross_rms' else ''
                            behind.append(f'{tn} {rate:g} Hz {lat * 1e3:g} ms: {c} {what}'
                                          f'{_mm(p[fig])} mm vs {_mm(m[fig])}')
        out[key] = {'worst_ratio': worst if cells else math.nan, 'behind': behind}
    return out


def ablation(lats=(0.0, 0.04, 0.1), rate: float = 50.0) -> str:
    """Where our shipped default loses to the stock LTV: the gain or the predictor?

    Ours on the figure eight (``rate`` Hz, RMS after 10 s, median of the seeds) with the
    shipped gain and with the bring-up's gain, each without and with the bring-up's
    predictor and limits (true latency, 50 ms lags, 1 m/s^2 and 3 rad/s^2).
    """
    from nonfragile_tracker.control.simulation.gains import read_gain_file
    from nonfragile_tracker.control.simulation.tracker import TrackerConfig
    traj, start, duration, settle = trajectory('figure eight')
    pc0 = adapter.base_plant(0.0, rate, 1)
    gains = {'shipped gain': read_gain_file(CONFIG / 'tracker_gains.yaml'),
             'bring-up gain': design_gain(*residual_interval(pc0), max(pc0.lag_v, pc0.lag_w))[0]}
    lines = ['| latency | ' + ' | '.join(f'{g}{p}' for g in gains
                                          for p in ('', ' + predictor')) + ' |',
             '|---' * 5 + '|']
    for lat in lats:
        cells = []
        for K in gains.values():
            for pred in (False, True):
                vals = []
                for seed in SEEDS:
                    pc = adapter.base_plant(lat, rate, seed, start)
                    kw = dict(predict_latency=lat, predict_lag_v=pc.lag_v, predict_lag_w=pc.lag_w,
                              max_linear_accel=pc.max_linear_accel,
                              max_angular_accel=pc.max_angular_accel) if pred else {}
                    sc = adapter.score(adapter.run(adapter.OURS, pc, TrackerConfig(
                        K=K, **scenario_tracker(), **kw), traj, duration), settle)
                    vals.append(math.inf if sc.diverged else sc.rms)
                cells.append(_mm(statistics.median(vals)))
        lines.append(f'| {lat * 1e3:g} ms | ' + ' | '.join(cells) + ' |')
    return '\n'.join(lines) + '\n'


def main(argv: list[str] | None = None) -> int:
    """Run the table (``--quick``: 50 Hz, two trajectories) and print / write it."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--quick', action='store_true', help='50 Hz, figure eight and line-arc lap')
    ap.add_argument('--jobs', type=int, default=0, help='worker processes (default: one per '
                    'CPU)')
    ap.add_argument('--out', default=None, help='markdown table (default: the full run writes '
                    'benchmarks/peers_table.md; --quick writes none)')
    ap.add_argument('--plot', default=None, help='plot (default: full run '
                    'doc/images/peers_latency.png)')
    ap.add_argument('--json', default=None, help='every run\'s figures as JSON')
    ap.add_argument('--controllers', default='', help='comma list of row labels (default all)')
    ap.add_argument('--ablation', action='store_true', help='only: ours on the figure eight '
                    'with the shipped / bring-up gain, without / with the predictor')
    ap.add_argument('--replot', default=None, metavar='TABLE',
                    help='only: draw the plot (--plot, default doc/images/peers_latency.png) '
                    'from a written table (benchmarks/peers_table.md) without running')
    args = ap.parse_args(argv)
    if args.replot:
        t = read_table(Path(args.replot))
        plot_path = Path(args.plot or ROOT / 'doc' / 'images' / 'peers_latency.png')
        plot(t['med'], t['controllers'], t['trajs'], t['rates'], t['lats'], plot_path)
        print(f'plot: {plot_path} ({len(t["med"])} cells of {args.replot})')
        return 0
    if args.ablation:
        print('figure eight, 50 Hz, RMS after 10 s (mm), median of 3 seeds\n')
        print(ablation())
        return 0
    import os
    t = run_table(args.quick, args.jobs or os.cpu_count() or 1, args.controllers,
                  log=lambda m: print(m, flush=True))
    controllers, trajs, rates, lats = t['controllers'], t['trajs'], t['rates'], t['lats']
    text = render(t['med'], controllers, trajs, rates, lats, tuple(t.get('followers', ())))
    a = ahead(t)
    head = (f'# Ours and the peers, side by side (issue 38)\n\n'
            f'`benchmarks/peers.py{" --quick" if args.quick else ""}`: {len(t["results"])} '
            f'runs, {t["wall"]:.0f} s wall.  Realistic base: 50 ms lag on v and w, 1 m/s^2 and '
            f'3 rad/s^2, 1 mm / 1 mrad odometry noise, command latency +0/10 ms jitter; '
            f'clamps |v| <= 1 m/s, |w| <= 2 rad/s for every controller; medians of '
            f'{len(SEEDS)} seeds; bold: the lowest RMS of the column (not diverged).\n')
    if t['skipped']:
        head += '\nSkipped peer modules: ' + '; '.join(f'{k} ({v})' for k, v in
                                                      t['skipped'].items()) + '\n'
    head += '\n**Ahead on every row?**  '
    for key, label in (('bringup', OURS_BRINGUP), ('identified', OURS_IDENTIFIED)):
        if math.isfinite(a[key]['worst_ratio']):
            head += (f'{label.capitalize()} / best peer (RMS), worst cell: '
                     f'{a[key]["worst_ratio"]:.2f}'
                     + (' (behind in: ' + '; '.join(a[key]['behind']) + ')'
                        if a[key]['behind'] else ' (ahead everywhere)') + '.  ')
    for key, label in (('untuned', 'Ours, shipped gain, monitor_tune off'),
                       ('default', 'Ours as shipped (monitor_tune on)')):
        if math.isfinite(a[key]['worst_ratio']):
            head += (f'{label} / best stock peer ({", ".join(t["stock"])}; path followers on '
                     f'cross-track) from 40 ms, worst cell: {a[key]["worst_ratio"]:.2f}'
                     + (' (behind in: ' + '; '.join(a[key]['behind']) + ')'
                        if a[key]['behind'] else ' (ahead everywhere)') + '.  ')
    head += '\n'
    print(head + text)
    out = args.out or (None if args.quick else str(HERE / 'peers_table.md'))
    if out:
        Path(out).write_text(head + text)
        print(f'table: {out}')
    plot_path = args.plot or (None if args.quick else str(ROOT / 'doc' / 'images' /
                                                           'peers_latency.png'))
    if plot_path:
        plot(t['med'], controllers, trajs, rates, lats, Path(plot_path))
        print(f'plot: {plot_path}')
    if args.json:
        Path(args.json).write_text(json.dumps(t['results'], indent=1, default=str))
    print(f'({t["wall"]:.0f} s wall)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
