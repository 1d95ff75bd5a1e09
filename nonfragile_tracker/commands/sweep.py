"""``sweep PROBLEM``: certified latency designs over a grid, in parallel, and their front.

See doc/cli.md, section "sweep".
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from .argtypes import add_executor_arguments, nonnegative_float, positive_float, positive_int
from .common import Subparsers, add_report_outputs, check_outputs

__all__ = ['register', 'run']


def run(args: argparse.Namespace) -> int:
    """Make the grid, design every point, print the table; JSON and plot if asked.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line of ``sweep``.
    """
    from ..control.synthesis.problem import load_problem
    from ..control.synthesis.sweep import (plot_sweep, records_for_json, run_sweep, sweep_points,
                                 sweep_table)
    check_outputs(args.force, args.json, args.plot)
    problem = load_problem(args.problem)
    latencies = args.latency or [[0.0, 0.03], [0.0, 0.15]]
    bounds = args.gain_bound or [None]
    predictors = {'both': [False, True], 'on': [True], 'off': [False]}[args.predictor]
    points = sweep_points(latencies, lags=args.lag or [0.0], gain_bounds=bounds,
                          objectives=args.objective or ['decay'], predictors=predictors)
    print(f'sweep of problem {problem.name!r}: {len(points)} designs on '
          + (f'Dask ({args.scheduler or "local cluster"})' if args.executor == 'dask'
             else 'local processes'), flush=True)
    t0 = time.perf_counter()
    records = run_sweep(problem, points, command_period=args.command_period,
                        executor=args.executor, workers=args.workers,
                        scheduler=args.scheduler)
    wall = time.perf_counter() - t0
    print(sweep_table(records))
    ok = sum(r['status'] == 'ok' for r in records)
    busy = sum(r['seconds'] for r in records)
    print(f'{ok} of {len(records)} designs certified (each verified in numpy; * Pareto front: '
          'certified command latency, decay rate, ||K||_2); '
          f'{wall:.1f} s wall, {busy:.1f} s of design time')
    if args.json:
        Path(args.json).write_text(json.dumps(
            {'problem': problem.name, 'command_period': args.command_period,
             'wall_time': wall, 'designs': records_for_json(records)}, indent=1,
            allow_nan=False))
        print(f'wrote {args.json}')
    if args.plot:
        plot_sweep(records, args.plot)
        print(f'wrote {args.plot}')
    return 0


def register(subparsers: Subparsers) -> None:
    """Add ``sweep`` to the CLI.

    Parameters
    ----------
    subparsers : argparse._SubParsersAction
        The CLI's sub-commands (``cli.build_parser``); ``sweep`` is added to them.
    """
    p = subparsers.add_parser(
        'sweep', help='certified latency designs over a grid (parallel), Pareto front',
        description='Design a certified tracker gain (latency-design) for every point of a '
        'grid of command latency interval x actuator lag x gain bound x objective, with '
        'and without the predictor, in parallel (local processes or Dask distributed); '
        'print a table, write every design with its certificate figures as JSON and plot '
        'the Pareto front of certified command latency against decay rate and ||K||_2.')
    p.add_argument('problem', help='problem YAML (e.g. config/paper_problem.yaml)')
    p.add_argument('--latency', nargs=2, type=nonnegative_float, action='append',
                   metavar=('LO', 'HI'), help='command latency interval in s (repeat for '
                   'several; default: 0 0.03 and 0 0.15)')
    p.add_argument('--lag', nargs='+', type=nonnegative_float,
                   help='actuator time constants in s (default: 0)')
    p.add_argument('--gain-bound', nargs='+', type=positive_float,
                   help='||K||_2 bounds (default: options.gain_bound of the problem)')
    p.add_argument('--objective', nargs='+', choices=['decay', 'max-delay'],
                   help='objectives (default: decay)')
    p.add_argument('--predictor', choices=['both', 'on', 'off'], default='both',
                   help='designs with the predictor at the low end of the latency (on: the '
                   'residual is certified), without it (off), or both (default; an interval '
                   'starting at 0 is designed once, the two being the same design)')
    p.add_argument('--command-period', type=positive_float, default=0.02,
                   help="the tracker's command period in s (default 0.02)")
    p.add_argument('--workers', type=positive_int, default=None,
                   help='worker processes (default: the cores available)')
    add_executor_arguments(p)
    add_report_outputs(p, json_help='write every design and its figures as JSON',
                       plot_help='write the Pareto-front plot')
    p.set_defaults(func=run)
