"""``study GAINS``: robustness study of a gain over sampled perturbations, latencies and poses.

See doc/cli.md, section "study", and doc/study.md.
"""
from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

from .argtypes import (add_executor_arguments, nonnegative_float, nonnegative_int,
                       positive_float, positive_int)
from .common import Subparsers, add_report_outputs, check_outputs

__all__ = ['register', 'cmd_study']


def _fmt(v: float | None, unit: str = '', prec: str = '.4g') -> str:
    return '-' if v is None else f'{v:{prec}}{unit}'


def cmd_study(args: argparse.Namespace) -> int:
    """Sample, run the batch, print the summary; write JSON and the plot if asked.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line of ``study``.
    """
    from ..control.simulation.batch import PathBatch
    from ..control.simulation.gains import read_gain_design, read_gain_file
    from ..control.synthesis.problem import load_problem
    from ..control.simulation.study import StudySpec, case_records, plot_study, run_study, summarize
    from ..errors import InputError
    from ..interface.msgconv import tracker_config_from
    from ..interface.resources import config_dir
    from ..interface.scenario import node_parameters, plant_config
    check_outputs(args.force, args.json, args.plot)
    K = read_gain_file(args.gains)
    design = read_gain_design(args.gains)
    problem = load_problem(args.problem or config_dir() / 'paper_problem.yaml')
    scenario = args.scenario or config_dir() / 'paper_scenario.yaml'
    plant = plant_config(node_parameters('plant', scenario))
    tparams = node_parameters('tracker', scenario)
    rparams = node_parameters('reference', scenario)
    if tparams.get('predict_latency') or tparams.get('predict_lag_v') \
            or tparams.get('predict_lag_w') or tparams.get('predict_odom_latency'):
        raise InputError(f'{scenario}: the study does not simulate the latency predictor '
                         '(predict_* tracker parameters); use a scenario without it')
    if tparams.get('max_linear_accel') or tparams.get('max_angular_accel'):
        raise InputError(f'{scenario}: the study does not simulate the tracker\'s command rate '
                         'limit (max_linear_accel, max_angular_accel tracker parameters); use a '
                         'scenario without it (the plant\'s limits are simulated)')
    # the tracker as the node maps its parameters (one mapping); the study samples Delta and
    # takes the plant's delay term
    tracker = tracker_config_from(
        tparams, K, dt=float(tparams.get('dt', plant.dt)), Delta=[0.0] * 4,
        delay_compensation=bool(args.delay_compensation),
        A_tau=[v for row in plant.A_tau for v in row], tau=plant.tau)
    center = list(rparams.get('center', [0.0, 0.0]))
    path = PathBatch(str(rparams.get('path', 'circle')), float(rparams.get('radius', 0.5)),
                     float(rparams.get('rate', 0.01)), float(center[0]), float(center[1]),
                     float(rparams.get('phase', 0.0)))
    path.path(0)                                     # a bad path is refused here (exit 2)
    spec = StudySpec(cases=args.cases, seed=args.seed, duration=args.duration,
                     latency=tuple(args.latency), lag=tuple(args.lag),
                     pose_spread=tuple(args.pose_spread), delta=args.delta,
                     delta_norm=tuple(args.delta_norm), hold=args.hold,
                     tolerance=args.tolerance)
    t0 = time.perf_counter()
    res = run_study(spec, plant, tracker, path, problem.E, problem.F, design, args.jobs,
                    executor=args.executor, scheduler=args.scheduler)
    wall = time.perf_counter() - t0
    summ = summarize(res)
    summ['wall_time'] = wall
    lim = res.limits
    print(f'study of {args.gains}: {spec.cases} cases x {spec.duration:g} s '
          f'({res.run.steps} steps of {plant.dt:g} s), {res.jobs} process(es)'
          + (' on Dask' if args.executor == 'dask' else '') + ', '
          f'{wall:.1f} s wall ({spec.cases * res.run.steps / max(wall, 1e-9):.3g} case-steps/s)')
    print(f'sampled: Delta {spec.delta} with ||Delta||_2 in [{spec.delta_norm[0]:g}, '
          f'{spec.delta_norm[1]:g}], command latency [{spec.latency[0]:g}, {spec.latency[1]:g}] s, '
          f'lag [{spec.lag[0]:g}, {spec.lag[1]:g}] s, pose spread {spec.pose_spread[0]:g} m / '
          f'{spec.pose_spread[1]:g} rad; seed {spec.seed}')
    cert = (f'{lim["latency"]:.4g} s (design record)' if lim['recorded']
            else '0 s (no certified latency in the gain file)')
    print(f'certified region: ||Delta||_2 <= 1 and loop latency <= {cert}'
          + (f'; with lag <= {lim["lag"]:g} s: latency <= {lim["lag_latency"]:.4g} s'
             if lim['lag'] > 0 else '; no actuator lag'))
    print(f'inside the certified region: {summ["inside_fraction"]:.1%} of the cases')
    head = (f'{"group":<9}{"cases":>7}{"settled":>9}{"diverged":>9}   settling time (s) '
            f'p50/p90/p99/max        steady error (m) p50/p90/p99/max')
    print(head)
    for name in ('all', 'inside', 'outside'):
        g = summ[name]
        st, se = g['settling_time'], g['steady_error']
        print(f'{name:<9}{g["cases"]:>7}{_fmt(g["settled_fraction"], "", ".1%"):>9}'
              f'{g["diverged"]:>9}   '
              + '/'.join(_fmt(st[k], '', '.3g') for k in ('p50', 'p90', 'p99', 'max')).ljust(32)
              + '/'.join(_fmt(se[k], '', '.3g') for k in ('p50', 'p90', 'p99', 'max')))
    for key, label in (('worst_steady_error', 'worst steady error'),
                       ('worst_settling_time', 'worst settling time')):
        w = summ[key]
        print(f'{label}: case {w["index"]} ({"inside" if w["inside"] else "outside"}; '
              f'||Delta|| {w["delta_norm"]:.3f}, latency {w["latency"]:.4g} s, lag '
              f'{w["lag_v"]:.3g}/{w["lag_w"]:.3g} s, pose ({w["x0"]:.3f}, {w["y0"]:.3f}, '
              f'{w["th0"]:.3f})): settling {_fmt(w["settling_time"], " s")}, steady error '
              f'{_fmt(w["steady_error"], " m")}')
    if args.json:
        data = dict(summ, gains=str(args.gains), cases=case_records(res))
        Path(args.json).write_text(json.dumps(data, indent=1, allow_nan=False,
                                              default=_json_default))
        print(f'wrote {args.json}')
    if args.plot:
        plot_study(res, args.plot)
        print(f'wrote {args.plot}')
    return 0


def _json_default(obj: object) -> None:
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    raise TypeError(f'not JSON serializable: {type(obj).__name__}')


def register(subparsers: Subparsers) -> None:
    """Add ``study`` to the CLI.

    Parameters
    ----------
    subparsers : argparse._SubParsersAction
        The CLI's sub-commands (``cli.build_parser``); ``study`` is added to them.
    """
    p = subparsers.add_parser(
        'study', help='robustness study: many sampled perturbations, latencies and poses',
        description='Simulate the tracking loop of a gain for many sampled cases at once '
        '(vectorized batch, split over processes) and report the worst case, the '
        'distribution of settling time and steady error, and the fraction of cases inside '
        'the certified region (||Delta||_2 <= 1, latency within the gain file\'s design '
        'record).')
    p.add_argument('gains', help='tracker gain file (e.g. config/tracker_gains.yaml)')
    p.add_argument('--problem', help='problem file for E, F (default config/paper_problem.yaml)')
    p.add_argument('--scenario', help='node parameter file: plant, reference, tracker limits '
                   '(default config/paper_scenario.yaml)')
    p.add_argument('--cases', type=positive_int, default=1000,
                   help='number of cases (default 1000)')
    p.add_argument('--seed', type=nonnegative_int, default=0, help='random seed (default 0)')
    p.add_argument('--duration', type=positive_float, default=60.0,
                   help='simulated seconds per case (default 60)')
    p.add_argument('--latency', type=nonnegative_float, nargs=2, metavar=('LO', 'HI'),
                   default=[0.0, 0.0], help='command latency range, s (default 0 0)')
    p.add_argument('--lag', type=nonnegative_float, nargs=2, metavar=('LO', 'HI'),
                   default=[0.0, 0.0], help='actuator time constant range of v and w, s '
                   '(default 0 0)')
    p.add_argument('--pose-spread', type=nonnegative_float, nargs=2, metavar=('M', 'RAD'),
                   default=[0.1, 0.3], help='initial position radius (m) and heading half-width '
                   '(rad) around the scenario pose (default 0.1 0.3)')
    p.add_argument('--delta', choices=['constant', 'switching', 'random'], default='constant',
                   help='Delta(t): constant, switching between two, or random every --hold s')
    p.add_argument('--delta-norm', type=nonnegative_float, nargs=2, metavar=('LO', 'HI'),
                   default=[0.0, 1.0], help='range of ||Delta||_2 (default 0 1; above 1 is '
                   'outside the certified region)')
    p.add_argument('--hold', type=positive_float, default=1.0,
                   help='segment length of a switching or random Delta, s (default 1)')
    p.add_argument('--tolerance', type=positive_float, default=0.01,
                   help='settling tolerance, m (default 0.01)')
    p.add_argument('--delay-compensation', action='store_true',
                   help='the zero steady-state error law (delay-consistent reference)')
    p.add_argument('--jobs', type=positive_int, default=None,
                   help='worker processes (default: the cores available)')
    add_executor_arguments(p, '--jobs')
    add_report_outputs(p, json_help='write the summary and every case as JSON',
                       plot_help='write a PNG of the distributions')
    p.set_defaults(func=cmd_study)
