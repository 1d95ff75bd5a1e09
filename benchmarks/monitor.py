#!/usr/bin/env python3
"""The certificate monitor on a latency step (issue 22, item 3): status and adaptation.

    .venv/bin/python benchmarks/monitor.py [--seeds 3] [--duration 60] [--json PATH]

In-process simulation through the step functions of the nodes (:func:`control.simulation.simulate.run_loop`;
a lockstep run gives the same commands) of issue 22's base: plant step 10 ms, 50 ms
first-order lag on v and w, acceleration limits 1 m/s^2 and 3 rad/s^2, odometry at 50 Hz
with 1 mm / 1 mrad noise, figure eight r = 1 m at 0.2 rad/s, tracker command period
20 ms.  The command latency is 100 ms and steps to 250 ms at 30 s
(``cmd_latency_schedule``).

Bring-up first (nothing hard-coded): a 30 s recording at 100 ms with the paper's ``K_nf``
and no predictor -> :func:`control.identification.identify.identify_latency` -> the plan rule
(:func:`control.synthesis.latency_design.plan_from_identification`) -> :func:`design_for_latency`
(the gain file ``latency-design --identification`` writes) -> its certificate
(:func:`control.identification.monitor.certificate_from_design`, the tracker's ``certified_*``).

Then per seed the step run with the monitor as the tracker node runs it (an estimate every
``--period`` s of simulated time over a 4 s window, :class:`control.identification.monitor.MonitorWorker`,
:func:`control.identification.monitor.evaluate`), with adaptation off, on (clamped to the identified
interval: the default) and on with the adaptation range widened to [0, 0.3] s (beyond what
was identified: shown for comparison).  Columns: status before the step, time from the
step to the first ERROR, the latency estimate at the end, the predictor's latency at the
end, RMS position error (true pose) over [40 s, end] and before the step [10, 30] s, and
the monitor's last message.  Side by side: today's shipped default gain with the
scenario's predictor (no bring-up).  Not a test: prints one table (medians over seeds).
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

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from nonfragile_tracker.control.simulation.gains import read_gain_design, read_gain_file  # noqa: E402
from nonfragile_tracker.control.identification.identify import (CommandSamples, OdometrySamples,  # noqa: E402
                                                 identify_latency)
from nonfragile_tracker.control.synthesis.latency_design import (design_for_latency,  # noqa: E402
                                                       plan_from_identification)
from nonfragile_tracker.control.simulation.plant import PlantConfig
from nonfragile_tracker.control.simulation.tracker import Tracker, TrackerConfig
from nonfragile_tracker.control.simulation.timing import step_time
from nonfragile_tracker.control.identification.monitor import (ERROR, LEVEL_NAMES, Certificate,  # noqa: E402
                                                MonitorSettings, MonitorWorker,
                                                adapted_prediction, certificate_from_design,
                                                evaluate)
from nonfragile_tracker.control.synthesis.problem import load_problem  # noqa: E402
from nonfragile_tracker.control.simulation.reference import figure_eight  # noqa: E402
from nonfragile_tracker.control.simulation.simulate import run_loop  # noqa: E402

CONFIG = ROOT / 'config'
DT, TRACKER_DT = 0.01, 0.02
LAG, ACCEL_V, ACCEL_W = 0.05, 1.0, 3.0
L0, L1, T_STEP = 0.1, 0.25, 30.0


def plant(seed: int, schedule=()) -> PlantConfig:
    """Issue 22's base with the latency schedule."""
    return PlantConfig(dt=DT, x0=0.0, y0=-0.1, th0=math.pi / 4, cmd_latency=L0, lag_v=LAG,
                       lag_w=LAG, max_linear_accel=ACCEL_V, max_angular_accel=ACCEL_W,
                       odom_rate=50.0, odom_noise=(1e-3, 1e-3, 1e-3), noise_seed=seed,
                       cmd_latency_schedule=tuple(schedule))


def run(K, predict: dict, seed: int, duration: float, schedule=(), monitor=None):
    """One run; ``monitor(t, tracker, window)`` is called every step with odometry."""
    tracker = Tracker(TrackerConfig(K=K, dt=TRACKER_DT, max_angular_speed=2.0, **predict))
    path = figure_eight(radius=1.0, rate=0.2)
    cmds, odom = [], []

    def command(meas, th, k, ref):
        ts = step_time(meas.step, DT)
        cmd = tracker.step(meas.x, meas.y, th, path.sample(ts), meas.v, stamp=ts)
        t_cmd = step_time(k, DT)
        cmds.append((t_cmd, cmd.v, cmd.w))
        odom.append((ts, meas.x, meas.y, th, meas.v, meas.w))
        if monitor is not None:
            monitor(ts, t_cmd, cmd, meas, tracker)
        return cmd

    res = run_loop(plant(seed, schedule), int(round(duration / DT)), command,
                   lambda k: path.sample(step_time(k, DT)))
    return res, np.array(cmds).T, np.array(odom).T


def rms(res, t0: float, t1: float = math.inf) -> float:
    """RMS of the true position error over [t0, t1] (m)."""
    sel = (res.t >= t0) & (res.t <= t1)
    e = res.error[sel]
    return float(np.sqrt(np.mean(e * e)))


def bring_up(seed: int) -> tuple[np.ndarray, dict, Certificate, str]:
    """Record -> identify -> latency-design at 100 ms; the gain, predictor and certificate."""
    K_nf = np.array(__import__('yaml').safe_load((CONFIG / 'paper_gains.yaml').read_text())
                    ['K_nf'])
    _, c, o = run(K_nf, {}, seed, 30.0)
    ident = identify_latency(CommandSamples(*c), OdometrySamples(*o), bootstrap=50)
    plan = plan_from_identification(ident, command_period=TRACKER_DT)
    problem = load_problem(CONFIG / 'paper_problem.yaml')
    t0 = time.perf_counter()
    des = design_for_latency(problem, plan.h_min, plan.h_max, lag=plan.lag)
    meta = {**des.metadata(), **plan.metadata()}
    cert = certificate_from_design(meta, hold=TRACKER_DT)
    assert cert is not None
    lo, hi = cert.interval(plan.predict_latency)
    text = (f'identified latency {ident.latency_s:.4f} s [{ident.latency_low_s:.4f}, '
            f'{ident.latency_high_s:.4f}], tau_v {ident.tau_v_s:.4f} s, tau_w '
            f'{ident.tau_w_s:.4f} s; residual to certify [{plan.h_min:.4f}, {plan.h_max:.4f}]'
            f' s, lag {plan.lag:.4f} s; design {time.perf_counter() - t0:.0f} s: certified '
            f'with the lag up to {des.lag_certified_h_max:.4f} s; monitor interval with '
            f'predict_latency {plan.predict_latency:.4f}: [{lo:.4f}, {hi:.4f}] s, adaptation range '
            f'{cert.adapt_range}')
    return des.K, plan.tracker_parameters(), cert, text


def step_run(K, predict, cert, seed, duration, period, adapt: bool,
             adapt_range=None) -> dict:
    """The latency-step run with the monitor every ``period`` s; its figures."""
    settings = MonitorSettings(max_linear_speed=1.0, max_angular_speed=2.0,
                               max_linear_accel=ACCEL_V, max_angular_accel=ACCEL_W)
    if adapt_range is not None and cert is not None:
        cert = Certificate(cert.residual, cert.lag, adapt_range, cert.hold, cert.source)
    worker = MonitorWorker(settings, period)
    log = []
    state = {'next': period}

    def monitor(ts, t_cmd, cmd, meas, tracker):
        worker.window.add_command(t_cmd, cmd.v, cmd.w)
        worker.window.add_odometry(ts, meas.v, meas.w)
        if ts + 1e-9 < state['next']:
            return
        state['next'] += period
        est = worker.update()
        pred = tracker.predictor
        P = pred.cmd_latency if pred is not None else 0.0
        if adapt and pred is not None and cert is not None:
            P = pred.cmd_latency = adapted_prediction(est, cert, P, settings)
        st = evaluate(est, cert, P, settings, adapting=adapt)
        log.append((ts, st.level, est.latency if est.valid else math.nan, P, st.message))

    res, _, _ = run(K, predict, seed, duration, (T_STEP, L1), monitor)
    before = [lv for t, lv, *_ in log if 10.0 <= t < T_STEP]
    after_err = [t for t, lv, *_ in log if t >= T_STEP and lv == ERROR]
    return {'status before': max(set(before), key=before.count) if before else -1,
            'levels before': sorted(set(before)),
            'to ERROR (s)': (after_err[0] - T_STEP) if after_err else math.inf,
            'L end': log[-1][2], 'P end': log[-1][3], 'level end': log[-1][1],
            'rms after': rms(res, T_STEP + 10.0), 'rms before': rms(res, 10.0, T_STEP),
            'message': log[-1][4], 'compute ms': 1e3 * worker.compute_seconds
            / max(worker.estimates, 1)}


def node_step_run(gain_file: Path, seed: int, duration: float, adapt: bool, run_dir: Path,
                  domain: int) -> dict:
    """The latency-step run through the nodes in real time; ERROR delay and RMS."""
    import os
    import re

    from nonfragile_tracker.workflows import runner
    sys.path.insert(0, str(ROOT / 'benchmarks'))
    from latency import bag_rms_after
    ov = {'plant': {'ros__parameters': {
        'cmd_latency': L0, 'noise_seed': seed, 'duration': duration,
        'max_linear_accel': ACCEL_V, 'max_angular_accel': ACCEL_W,
        'cmd_latency_schedule': [T_STEP, L1]}},
        'tracker': {'ros__parameters': {'monitor_adapt': adapt}}}
    runner.merge(ov, runner.realtime_overrides())
    params = runner.scenario_parameters(CONFIG / 'latency_scenario.yaml', gain_file, ov)
    run_dir.mkdir(parents=True)
    env = runner.isolated_env({**os.environ, 'ROS_DOMAIN_ID': str(domain)})
    res = runner.run_processes(params, run_dir, record=True, env=env, timeout=300.0,
                               progress=lambda _line: None, record_all=True)
    from nonfragile_tracker.bag.reader import read_messages
    stamps = [m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec
              for _, m in read_messages(res.bag, 'pose')]
    start = stamps[-1] - duration
    log = (run_dir / 'tracker.log').read_text()
    errors = [float(m.group(1)) for m in re.finditer(
        r'\[ERROR\] \[(\d+\.\d+)\] \[tracker\]: certificate ERROR', log)]
    after = [t - (start + T_STEP) for t in errors if t >= start + T_STEP - 1.0]
    last = [ln for ln in log.splitlines() if 'certificate' in ln][-1:]
    return {'to ERROR (s)': after[0] if after else math.inf,
            'rms after': bag_rms_after(res.bag, duration, T_STEP + 10.0),
            'last': last[0][:300] if last else '', 'exit': res.exit_codes}


def main_nodes(args) -> int:
    """Bring-up in process, then the step through the nodes in real time."""
    import tempfile

    from nonfragile_tracker.control.simulation.gains import write_gain_file
    K, predict, cert, text = bring_up(seed=11)
    print('bring-up:', text)
    tmp = Path(tempfile.mkdtemp(prefix='monitor_bench_'))
    extra = {**predict, **cert.parameters(), 'max_angular_speed': 2.0}
    gain_file = write_gain_file(tmp / 'bringup.yaml', K, extra=extra)
    wide = write_gain_file(tmp / 'bringup_wide.yaml', K,
                           extra={**extra, 'certified_adapt_range': [0.0, 0.3]})
    print('| mode | adaptation | step -> ERROR (s) | RMS from 40 s (mm) |')
    print('|---|---|---|---|')
    cases = [('off', gain_file, False), ('on (identified range)', gain_file, True),
             ('on, range widened to [0, 0.3] s', wide, True)]
    for i, (name, gf, adapt) in enumerate(cases):
        for seed in range(1, args.seeds + 1):
            r = node_step_run(gf, seed, args.duration, adapt, tmp / f'run_{i}_{seed}',
                              60 + seed + 10 * i)
            print(f"| real time | {name} | {r['to ERROR (s)']:.1f} | "
                  f"{1e3 * r['rms after']:.1f} |   exit {r['exit']}; {r['last']}")
    return 0


def main() -> int:
    """Bring-up, then the table."""
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--nodes', action='store_true', help='through the ROS nodes, real time')
    ap.add_argument('--seeds', type=int, default=3)
    ap.add_argument('--duration', type=float, default=60.0)
    ap.add_argument('--period', type=float, default=1.0, help='seconds between estimates')
    ap.add_argument('--json', help='write the rows here')
    args = ap.parse_args()
    if args.nodes:
        return main_nodes(args)
    K, predict, cert, text = bring_up(seed=11)
    print('bring-up (record 30 s with K_nf, no predictor, at 100 ms):', text)
    default_K = read_gain_file(CONFIG / 'tracker_gains.yaml')
    default_cert = certificate_from_design(read_gain_design(CONFIG / 'tracker_gains.yaml'),
                                           hold=TRACKER_DT)
    scen_predict = dict(predict_latency=L0, predict_lag_v=LAG, predict_lag_w=LAG)
    cases = [
        ('shipped default + scenario predictor', default_K, scen_predict, default_cert, False,
         None),
        ('bring-up gain, adaptation off', K, predict, cert, False, None),
        ('bring-up gain, adaptation on (clamped to identified)', K, predict, cert, True, None),
        ('bring-up gain, adaptation on, range widened to [0, 0.3] s', K, predict, cert, True,
         (0.0, 0.3)),
    ]
    rows = []
    for name, k, pr, ce, adapt, rng in cases:
        runs = [step_run(k, pr, ce, seed, args.duration, args.period, adapt, rng)
                for seed in range(1, args.seeds + 1)]
        med = {key: statistics.median(r[key] for r in runs)
               for key in ('to ERROR (s)', 'L end', 'P end', 'rms after', 'rms before',
                           'compute ms')}
        rows.append({'case': name, **med,
                     'status before': [LEVEL_NAMES.get(r['status before'], '-') for r in runs],
                     'status end': [LEVEL_NAMES[r['level end']] for r in runs],
                     'message': runs[0]['message']})
    print(f'\nlatency {L0 * 1e3:.0f} -> {L1 * 1e3:.0f} ms at {T_STEP:g} s; median of '
          f'{args.seeds} seeds; RMS of the true position error\n')
    print('| case | status 10-30 s | step -> ERROR (s) | L est. end (ms) | predict_latency '
          'end (ms) | status end | RMS 10-30 s (mm) | RMS from 40 s (mm) |')
    print('|---|---|---|---|---|---|---|---|')
    for r in rows:
        print(f"| {r['case']} | {'/'.join(r['status before'])} | {r['to ERROR (s)']:.1f} | "
              f"{1e3 * r['L end']:.0f} | {1e3 * r['P end']:.0f} | {'/'.join(r['status end'])} "
              f"| {1e3 * r['rms before']:.1f} | {1e3 * r['rms after']:.1f} |")
    print('\nlast message per case (seed 1):')
    for r in rows:
        print(f"- {r['case']}: {r['message']}")
    print(f"\nestimate cost: {statistics.median(r['compute ms'] for r in rows):.1f} ms each")
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=2, default=str))
    return 0


if __name__ == '__main__':
    sys.exit(main())
