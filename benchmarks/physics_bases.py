"""Issue 39: the MuJoCo bases (``config/bases/``) identified and tracked, against the model.

Per base (TurtleBot3 Burger-like, Jackal-like two-wheel, Jackal-like skid-steer), in process
(``nonfragile_tracker.control.simulation.physics``, no ROS):

* **sim speed** - simulated s per wall s of a bare plant under a constant command and of the
  tracking loop (figure eight, our tracker) through ``simulate_following``;
* **static gains, truth** - the true speed and yaw rate over the command at steady state
  (``physics.static_gains``: a straight run, an arc, the skid-steer also on the spot);
* **response, truth** - a small step of v and of w (no ramp binds): the time to 10 % and to
  63 % of the true speed's step, beside the configured command latency;
* **identified** - ``identify_latency`` on 20 s of random steps (20 Hz commands) through the
  base's own odometry: latency, lags, gains, acceleration limits (truth: the firmware's
  ramps; 0 = not seen to bind);
* **side slip** - ``identify_side_slip`` on the same drive against the true pose (1 mm
  noise, as a motion capture gives it): the table at 0.25 and 0.5 rad/s, the lateral drift
  it explains, compensated when significant;
* **tracking** - the figure eight with the shipped gain and the predictor set from the
  identification (gains and side slip compensated; the skid-steer also with the turn gain
  only and with neither): true-pose RMS after 5 s,
  the RMS in the odometry frame (what the tracker sees) and the odometry's final drift.

Two conditions: ``ideal`` (no command latency, odometry every 10 ms step) and ``late`` (50 ms
command latency, 50 Hz odometry).  Timings are the median of ``--repeat`` runs (default 3;
the figures themselves are deterministic, bit-identical across runs).

``--nodes DIR``: issue 39 item 4 through the nodes instead, one run per base: ``bringup
--simulate config/bases/<base>.yaml`` (real time; the TurtleBot3 with a robot file limiting
it to 0.15 m/s, where its outer wheel stays below the motors' no-load speed in the lap's
0.4 m arcs), then with the gain file it wrote the figure eight (``run --scenario``, lockstep,
40 s) and the line-arc lap (``run --trajectory config/trajectories/line_arc_lap.csv``), each
recorded with the true pose (``--record-all``): the true-pose RMS after 10 s (the eight) or
2 s (the lap), the same of the odometry's pose (what the tracker sees: its estimate less the
side slip it compensates) and the odometry's drift.

Usage::

    .venv/bin/python benchmarks/physics_bases.py [--repeat 3] [--json PATH]
    .venv/bin/python benchmarks/physics_bases.py --nodes /tmp/physics_nodes

Prints one Markdown table per condition on stdout (progress on stderr).
"""
from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from nonfragile_tracker.control.identification.identify import (  # noqa: E402
    CommandSamples, OdometrySamples, identify_latency)
from nonfragile_tracker.control.identification.slip import identify_side_slip  # noqa: E402
from nonfragile_tracker.control.simulation import physics  # noqa: E402
from nonfragile_tracker.control.simulation.follow import simulate_following  # noqa: E402
from nonfragile_tracker.control.simulation.gains import read_gain_file  # noqa: E402
from nonfragile_tracker.control.simulation.plant import PlantConfig
from nonfragile_tracker.control.simulation.tracker import TrackerConfig
from nonfragile_tracker.control.simulation.timing import step_time
from nonfragile_tracker.control.simulation.reference import figure_eight  # noqa: E402
from nonfragile_tracker.control.simulation.trajectory import Trajectory  # noqa: E402

GAIN = ROOT / 'config' / 'tracker_gains.yaml'
#: Figure eight per base (radius m, rate rad/s, seconds), as test/control/test_physics.py.
EIGHTS = {'turtlebot3': (0.4, 0.3, 25.0), 'jackal': (1.0, 0.2, 25.0),
          'jackal_skid': (1.0, 0.2, 25.0)}
#: Static-gain commands per base (v, w).
STATIC = {'turtlebot3': [(0.15, 0.0), (0.1, 1.0)], 'jackal': [(1.0, 0.0), (0.5, 1.0)],
          'jackal_skid': [(1.0, 0.0), (0.5, 1.0), (0.0, 1.0)]}
CONDITIONS = {'ideal': dict(dt=0.01), 'late': dict(dt=0.01, cmd_latency=0.05, odom_rate=50.0)}


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def bare_speed(base: str, seconds: float = 10.0) -> float:
    """Simulated s per wall s of the plant alone (constant command, nothing else)."""
    plant = physics.PhysicsPlant(PlantConfig(dt=0.01), base)
    v = 0.5 * min(plant.spec.max_linear_speed, 1.0)
    t0 = time.perf_counter()
    for _ in range(int(round(seconds / plant.dt))):
        plant.command(v, 0.3)
        plant.advance()
    return seconds / (time.perf_counter() - t0)


def step_response(base: str, channel: str, latency: float) -> tuple[float, float]:
    """Times (s) from a small command step to 10 % and 63 % of the true speed's step."""
    plant = physics.PhysicsPlant(PlantConfig(dt=0.01, cmd_latency=latency), base)
    size = 0.02 if channel == 'v' else 0.1              # below every ramp in one step
    rows = []
    for _ in range(150):
        plant.command(size if channel == 'v' else 0.0, size if channel == 'w' else 0.0)
        plant.advance()
        rows.append(plant.v if channel == 'v' else plant.w)
    y = np.array(rows) / np.mean(rows[-30:])
    t = (np.arange(len(rows)) + 1) * plant.dt
    return float(t[np.argmax(y >= 0.1)]), float(t[np.argmax(y >= 0.632)])


def identify(base: str, condition: dict) -> object:
    """``identify_latency`` on 20 s of random steps through the base's odometry, and the side
    slip from the true pose beside it (1 mm noise): the table when it is significant."""
    from dataclasses import replace
    plant = physics.PhysicsPlant(PlantConfig(**condition), base)
    rng = np.random.default_rng(3)
    vmax = min(plant.spec.max_linear_speed, 1.0)
    levels = [(rng.uniform(0.1, 0.5) * vmax, rng.uniform(-1.0, 1.0)) for _ in range(20)]
    cmd, odom, truth = [], [], []
    for k in range(2000):
        s = plant.odometry()
        if s is not None:
            t = step_time(s.step, plant.dt)
            odom.append((t, s.x, s.y, s.th, s.v, s.w))
            truth.append((t, plant.x + rng.normal(0.0, 1e-3), plant.y + rng.normal(0.0, 1e-3),
                          plant.th))
        if k % 5 == 0:
            v, w = levels[k // 100]
            plant.command(v, w)
            cmd.append((step_time(k, plant.dt), v, w))
        plant.advance()
    o = OdometrySamples(*np.array(odom).T)
    ident = identify_latency(CommandSamples(*np.array(cmd).T), o)
    slip = identify_side_slip(o, OdometrySamples(*np.array(truth).T))
    SLIPS[(base, str(condition))] = slip
    if slip.significant:
        ident = replace(ident, side_slip_rates=slip.rates, side_slip=slip.coefficients)
    return ident


#: The side slip of each identification, by (base, condition).
SLIPS: dict = {}


def track(base: str, condition: dict, ident: object, compensate: bool = True,
          slip: bool = True) -> dict:
    """The figure eight on ``base``: RMS figures (m) and the loop's sim speed."""
    radius, rate, seconds = EIGHTS[base]
    path = figure_eight(radius=radius, rate=rate)
    odom: list[tuple[float, float, float]] = []

    class Logged(physics.PhysicsPlant):
        def advance(self) -> None:
            super().advance()
            odom.append(self.odom_pose)

    pc = PlantConfig(th0=path.rest_heading, **condition)
    spec = physics.PhysicsPlant(pc, base).spec
    tc = TrackerConfig(K=read_gain_file(GAIN), max_linear_speed=spec.max_linear_speed,
                       max_angular_speed=spec.max_angular_speed,
                       predict_latency=ident.latency_s, predict_lag_v=ident.tau_v_s,
                       predict_lag_w=ident.tau_w_s,
                       gain_v=ident.gain_v if compensate else 1.0,
                       gain_w=ident.gain_w if compensate else 1.0,
                       side_slip_rates=ident.side_slip_rates if slip else (),
                       side_slip=ident.side_slip if slip else ())
    t0 = time.perf_counter()
    run = simulate_following(pc, tc, Trajectory.analytic(path), int(round(seconds / pc.dt)),
                             plant=lambda c: Logged(c, base))
    wall = time.perf_counter() - t0
    o = np.array([(pc.x0, pc.y0, pc.th0)] + odom)
    after = run.t >= 5.0
    seen = np.hypot(o[:, 0] - run.xd, o[:, 1] - run.yd)
    return {'true_rms': math.sqrt(float(np.mean(run.error[after] ** 2))),
            'true_max': float(run.error[after].max()),
            'odom_rms': math.sqrt(float(np.mean(seen[after] ** 2))),
            'drift': math.hypot(o[-1, 0] - run.x[-1], o[-1, 1] - run.y[-1]),
            'speed': seconds / wall}


def measure(repeat: int) -> dict:
    """Every figure of every base and condition (timings: each repetition kept)."""
    out: dict = {}
    for base in physics.BASES:
        spec = physics.PhysicsPlant(PlantConfig(dt=0.01), base).spec
        row: dict = {'limits': (spec.max_linear_accel, spec.max_angular_accel)}
        log(f'{base}: bare speed, static gains, step responses')
        row['bare_speed'] = [bare_speed(base) for _ in range(repeat)]
        row['static'] = {f'{v:g},{w:g}': physics.static_gains(base, v, w)
                         for v, w in STATIC[base]}
        for name, cond in CONDITIONS.items():
            lat = cond.get('cmd_latency', 0.0)
            c: dict = {'latency_truth': lat,
                       'step_v': step_response(base, 'v', lat),
                       'step_w': step_response(base, 'w', lat)}
            log(f'{base} {name}: identification')
            ident = identify(base, cond)
            c['identified'] = {k: getattr(ident, k) for k in (
                'latency_s', 'latency_low_s', 'latency_high_s', 'tau_v_s', 'tau_w_s', 'gain_v',
                'gain_v_low', 'gain_v_high', 'gain_w', 'gain_w_low', 'gain_w_high',
                'max_linear_accel', 'max_angular_accel', 'excluded_s')}
            log(f'{base} {name}: tracking x {repeat}')
            runs = [track(base, cond, ident) for _ in range(repeat)]
            c['track'] = {k: runs[0][k] for k in runs[0] if k != 'speed'}
            c['track']['speed'] = [r['speed'] for r in runs]
            assert all(r['true_rms'] == runs[0]['true_rms'] for r in runs), 'not deterministic'
            sl = SLIPS[(base, str(cond))]
            c['side_slip'] = {'rates': sl.rates, 'c': sl.coefficients, 'low': sl.low,
                              'high': sl.high, 'drift_rms': sl.drift_rms,
                              'residual_rms': sl.residual_rms, 'significant': sl.significant}
            if base == 'jackal_skid':
                c['track_uncompensated'] = track(base, cond, ident, compensate=False,
                                                 slip=False)
                c['track_gain_only'] = track(base, cond, ident, slip=False)
            row[name] = c
        out[base] = row
    return out


def _slip_cell(sl: dict) -> str:
    parts = [f"{r:g}: {sl['c'][j]:.3f} ({sl['low'][j]:.3f}-{sl['high'][j]:.3f})"
             for j, r in enumerate(sl['rates'])]
    return (' / '.join(parts) + f"; {1e3 * sl['drift_rms']:.2f} -> "
            f"{1e3 * sl['residual_rms']:.2f}" + ('' if sl['significant'] else
                                                 ' (not significant: not compensated)'))


def _med(xs: list[float]) -> str:
    return f'{statistics.median(xs):.0f} ({min(xs):.0f}-{max(xs):.0f})'


def table(res: dict, condition: str) -> str:
    """One Markdown table of ``condition`` (rows: figures, columns: bases)."""
    bases = list(res)
    lines = [f'| {condition} | ' + ' | '.join(bases) + ' |',
             '|---|' + '---|' * len(bases)]

    def row(name: str, cell) -> None:
        lines.append(f'| {name} | ' + ' | '.join(cell(res[b]) for b in bases) + ' |')

    row('sim speed, bare plant (sim s / wall s)', lambda r: _med(r['bare_speed']))
    row('sim speed, tracking loop', lambda r: _med(r[condition]['track']['speed']))
    row('static gains v, w (truth; per command v,w)', lambda r: '; '.join(
        f'{k}: ' + '/'.join('-' if math.isnan(g) else f'{g:.4f}' for g in gs)
        for k, gs in r['static'].items()))
    row('step response v: 10 % / 63 % (ms)', lambda r: '%.0f / %.0f' % tuple(
        1e3 * t for t in r[condition]['step_v']))
    row('step response w: 10 % / 63 % (ms)', lambda r: '%.0f / %.0f' % tuple(
        1e3 * t for t in r[condition]['step_w']))
    row('command latency configured (ms)', lambda r: f"{1e3 * r[condition]['latency_truth']:.0f}")
    row('identified latency (ms, interval)', lambda r: '%.1f (%.1f-%.1f)' % tuple(
        1e3 * r[condition]['identified'][k] for k in ('latency_s', 'latency_low_s',
                                                       'latency_high_s')))
    row('identified lags v / w (ms)', lambda r: '%.1f / %.1f' % tuple(
        1e3 * r[condition]['identified'][k] for k in ('tau_v_s', 'tau_w_s')))
    row('identified gains v / w (95 % interval)', lambda r: '%.4f (%.4f-%.4f) / %.4f '
        '(%.4f-%.4f)' % tuple(r[condition]['identified'][k] for k in (
            'gain_v', 'gain_v_low', 'gain_v_high', 'gain_w', 'gain_w_low', 'gain_w_high')))
    row('identified accel limits (truth)', lambda r: '%.2f / %.2f (%.1f / %.1f)' % (
        r[condition]['identified']['max_linear_accel'],
        r[condition]['identified']['max_angular_accel'], *r['limits']))
    row('identified side slip c (s) per rate (rad/s; 95 % interval); window drift -> '
        'residual (mm)', lambda r: _slip_cell(r[condition]['side_slip']))
    row('figure eight: true-pose RMS after 5 s (mm)', lambda r: (
        f"{1e3 * r[condition]['track']['true_rms']:.2f}" + (
            f" (turn gain only {1e3 * r[condition]['track_gain_only']['true_rms']:.2f}, "
            f"uncompensated {1e3 * r[condition]['track_uncompensated']['true_rms']:.2f})"
            if 'track_uncompensated' in r[condition] else '')))
    row('figure eight: true-pose max after 5 s (mm)',
        lambda r: f"{1e3 * r[condition]['track']['true_max']:.2f}")
    row('figure eight: RMS in the odometry frame (mm)', lambda r: (
        f"{1e3 * r[condition]['track']['odom_rms']:.2f}" + (
            f" (uncompensated {1e3 * r[condition]['track_uncompensated']['odom_rms']:.2f})"
            if 'track_uncompensated' in r[condition] else '')))
    row('odometry drift at the end (mm)', lambda r: f"{1e3 * r[condition]['track']['drift']:.1f}")
    return '\n'.join(lines)


#: Robot-file limits per base for ``--nodes`` (max_linear_speed, max_angular_speed).
ROBOT_LIMITS = {'turtlebot3': (0.15, 2.84), 'jackal': (1.0, 2.0), 'jackal_skid': (1.0, 2.0)}
#: The bring-up's options per base: at the lap's speed.  The Jackals' lap cruises at 0.4 m/s
#: into 0.4 m arcs (1 rad/s; the skid-steer commands 1.6 rad/s for it): --max-speed 0.5 (the
#: excitation's top speed is 0.8 of it) and the robot file's 2 rad/s.  The TurtleBot3's lap
#: runs at its robot file's 0.15 m/s, which the default bring-up (0.3 m/s, the lower wins;
#: 1 rad/s) covers; at its published 2.84 rad/s its wheels saturate near 1 rad/s at speed.
BRINGUP_ARGS = {'turtlebot3': (), 'jackal': ('--max-speed', '0.5', '--max-turn-rate', '2'),
                'jackal_skid': ('--max-speed', '0.5', '--max-turn-rate', '2')}


def cli(*args: str) -> str:
    """The package's CLI (``python -m nonfragile_tracker.cli``); its stdout, or raises."""
    import subprocess
    res = subprocess.run([sys.executable, '-m', 'nonfragile_tracker.cli', *args], cwd=ROOT,
                         capture_output=True, text=True)
    if res.returncode != 0:
        raise RuntimeError(f'{" ".join(args)} failed ({res.returncode}):\n{res.stdout[-3000:]}'
                           f'\n{res.stderr[-3000:]}')
    return res.stdout + res.stderr


def true_pose_figures(bag: Path, after: float) -> dict:
    """True-pose RMS / max (the ``pose`` topic against the reference) after ``after`` s and
    the odometry's drift from the true pose (final, max), in m."""
    from nonfragile_tracker.bag.reader import read_bag, read_messages
    run = read_bag(bag).run
    truth = {}
    for _, msg in read_messages(bag, 'pose'):
        st = msg.header.stamp
        truth[st.sec * 10**9 + st.nanosec] = (msg.pose.position.x, msg.pose.position.y)
    ref = {int(s): (x, y) for s, x, y in zip(run.reference.stamp_ns, run.reference.x,
                                             run.reference.y)}
    odom = {int(s): (x, y) for s, x, y in zip(run.pose.stamp_ns, run.pose.x, run.pose.y)}
    t0 = min(truth)
    stamps = [ns for ns in sorted(truth) if ns in ref and ns in odom]
    t = (np.array(stamps, dtype=float) - t0) * 1e-9
    e = np.array([math.dist(truth[ns], ref[ns]) for ns in stamps])
    d = np.array([math.dist(truth[ns], odom[ns]) for ns in stamps])
    o = np.array([math.dist(odom[ns], ref[ns]) for ns in stamps])
    m = t >= after
    return {'true_rms': math.sqrt(float(np.mean(e[m] ** 2))), 'true_max': float(e[m].max()),
            'drift_final': float(d[-1]), 'drift_max': float(d.max()),
            'odom_rms': math.sqrt(float(np.mean(o[m] ** 2)))}


def nodes(out_dir: Path) -> dict:
    """Item 4 through the nodes: a bring-up per base, then the eight and the lap with its files."""
    import re
    out_dir.mkdir(parents=True, exist_ok=True)
    res: dict = {}
    robot = (ROOT / 'config' / 'robot.yaml').read_text()
    for base in physics.BASES:
        v, w = ROBOT_LIMITS[base]
        robot_file = out_dir / f'{base}_robot.yaml'
        robot_file.write_text(re.sub(r'max_angular_speed: [0-9.]+', f'max_angular_speed: {w}',
                                     re.sub(r'max_linear_speed: [0-9.]+',
                                            f'max_linear_speed: {v}', robot)))
        scenario = f'config/bases/{base}.yaml'
        log(f'{base}: bringup --simulate {scenario} (real time, about 80 s)')
        # driven at the lap's speed: what it identifies holds where the lap drives
        text = cli('bringup', '--simulate', scenario, '--robot', str(robot_file), '--out',
                   str(out_dir), '--name', f'{base}_bringup', *BRINGUP_ARGS[base])
        row: dict = {'bringup': [ln for ln in text.splitlines()
                                 if re.match(r'\[bringup\] (identified|designed|trial):', ln)]}
        gains = out_dir / f'{base}_bringup' / 'gains.yaml'
        head = gains.read_text().split('gain_design:')[0]
        row['gain_w'] = 'gain_w:' in head
        row['side_slip'] = 'side_slip:' in head
        row['bringup'] += [ln for ln in text.splitlines() if ln.startswith('[bringup] side slip')]
        for name, extra, after in (('eight', [], 10.0), ('lap', [
                '--trajectory', 'config/trajectories/line_arc_lap.csv', '--duration', '60'],
                2.0)):
            log(f'{base}: the {name} with the files the bring-up wrote')
            cli('run', '--scenario', scenario, '--gains', str(gains), '--record-all',
                       '--out', str(out_dir), '--name', f'{base}_{name}', *extra)
            row[name] = true_pose_figures(out_dir / f'{base}_{name}' / 'bag', after)
        res[base] = row
    return res


def nodes_median(runs: list[dict]) -> dict:
    """Several ``nodes`` results as one: each figure the median of the runs (``*_all``: every
    run's true-pose RMS), the bring-up's lines and flags those of the first run."""
    out: dict = {}
    for base in runs[0]:
        row = dict(runs[0][base])
        for name in ('eight', 'lap'):
            figs = [r[base][name] for r in runs]
            row[name] = {k: statistics.median(f[k] for f in figs) for k in figs[0]}
            row[name]['true_rms_all'] = [f['true_rms'] for f in figs]
        row['runs'] = len(runs)
        out[base] = row
    return out


def _rms_cell(fig: dict) -> str:
    cell = '%.2f / %.2f' % (1e3 * fig['true_rms'], 1e3 * fig['true_max'])
    runs = fig.get('true_rms_all', [])
    if len(runs) > 1:
        cell += ' (RMS %.2f-%.2f over %d runs)' % (1e3 * min(runs), 1e3 * max(runs), len(runs))
    return cell


def nodes_table(res: dict) -> str:
    """The ``--nodes`` table (rows: figures, columns: bases; medians with ``--repeat``)."""
    bases = list(res)
    lines = ['| through the nodes (bring-up, then its files) | ' + ' | '.join(bases) + ' |',
             '|---|' + '---|' * len(bases)]
    for name, cell in (
            ('bring-up: identified', lambda r: next((ln.split(': ', 1)[1] for ln in r['bringup']
                                                     if 'identified' in ln), '-')),
            ('bring-up: trial', lambda r: next((ln.split(': ', 1)[1].split(';')[0]
                                                for ln in r['bringup'] if 'trial' in ln), '-')),
            ('gain_w compensated', lambda r: 'yes' if r['gain_w'] else 'no'),
            ('side slip compensated (identified from the true pose)',
             lambda r: 'yes' if r.get('side_slip') else 'no'),
            ('eight: true-pose RMS / max after 10 s (mm)', lambda r: _rms_cell(r['eight'])),
            ('eight: odometry-frame RMS after 10 s (mm)',
             lambda r: f"{1e3 * r['eight']['odom_rms']:.2f}"),
            ('eight: odometry drift final / max (mm)', lambda r: '%.1f / %.1f' % (
                1e3 * r['eight']['drift_final'], 1e3 * r['eight']['drift_max'])),
            ('lap: true-pose RMS / max after 2 s (mm)', lambda r: _rms_cell(r['lap'])),
            ('lap: odometry-frame RMS after 2 s (mm)',
             lambda r: f"{1e3 * r['lap']['odom_rms']:.2f}"),
            ('lap: odometry drift final / max (mm)', lambda r: '%.1f / %.1f' % (
                1e3 * r['lap']['drift_final'], 1e3 * r['lap']['drift_max']))):
        lines.append(f'| {name} | ' + ' | '.join(cell(res[b]) for b in bases) + ' |')
    return '\n'.join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--repeat', type=int, help='repetitions, medians (default 3 in process: the '
                    'timings; 1 with --nodes)')
    ap.add_argument('--json', type=Path, help='write every raw figure here')
    ap.add_argument('--nodes', type=Path, metavar='DIR',
                    help='item 4 through the nodes instead (bring-up, eight, lap per base; '
                    '--repeat runs of each, default 1 here, medians)')
    ap.add_argument('--from-json', type=Path, nargs='+', metavar='JSON',
                    help='with --nodes: the table of earlier runs\' JSON files (medians)')
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    if args.nodes:
        repeat = args.repeat or 1
        if args.from_json:
            runs = [json.loads(f.read_text()) for f in args.from_json]
        else:
            runs = []
            for i in range(repeat):
                d = args.nodes if repeat == 1 else args.nodes / f'run{i + 1}'
                runs.append(nodes(d))
                (d / 'nodes.json').write_text(json.dumps(runs[-1], indent=1))
        res = nodes_median(runs)
        print(nodes_table(res))
        print(f'({len(runs)} run(s) per base, medians; {time.perf_counter() - t0:.0f} s in all)')
        if args.json:
            args.json.write_text(json.dumps(res, indent=1))
        return 0
    args.repeat = args.repeat or 3
    res = measure(args.repeat)
    for condition in CONDITIONS:
        print(table(res, condition))
        print()
    print(f'(median of {args.repeat}, min-max; {time.perf_counter() - t0:.0f} s in all)')
    if args.json:
        args.json.write_text(json.dumps(res, indent=1))
    return 0


if __name__ == '__main__':
    sys.exit(main())
