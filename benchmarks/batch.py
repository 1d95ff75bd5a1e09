#!/usr/bin/env python3
"""Batch simulation against the single run (issue 15, item 1-2).  Standalone, one table.

    .venv/bin/python benchmarks/batch.py [--quick] [--reps R]

Rows (paper scenario: config/paper_scenario.yaml plant, config/tracker_gains.yaml gain):

* ``single run``: ``simulate_tracking`` steps/s (3,000 steps), measured right before
  each batch repetition: each ratio is batch / the single run just before it (the
  machine's load moves both alike), the column gives their median and range;
* ``batch N`` (one process): ``simulate_batch`` case-steps/s for N = 1,000 and 10,000
  (per-case constant Delta and initial pose), ratio to the single run (target >= 100 x);
* ``batch N, J processes``: the same cases split over the available cores as the study
  does (``run_study``), ratio to the single run;
* ``study 10,000 x 60 s``: ``run_study`` of the paper scenario (Delta in the unit ball,
  command latency 0-0.3 s, pose spread 0.1 m / 0.3 rad), wall time (target < 120 s).

Median over ``--reps`` repetitions (min-max beside it).  The machine is shared: the
header gives the load average; figures under load are lower than on a quiet machine.
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))
os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')

import numpy as np  # noqa: E402

from nonfragile_tracker.control.batch import (BatchCases, PathBatch,  # noqa: E402
                                              perturbation_schedule, sample_deltas,
                                              simulate_batch)
from nonfragile_tracker.control.gains import read_gain_design, read_gain_file  # noqa: E402
from nonfragile_tracker.control.loop import TrackerConfig  # noqa: E402
from nonfragile_tracker.control.problem import load_problem  # noqa: E402
from nonfragile_tracker.control.reference import circle  # noqa: E402
from nonfragile_tracker.control.simulate import simulate_tracking  # noqa: E402
from nonfragile_tracker.control.study import StudySpec, default_jobs, run_study  # noqa: E402
from nonfragile_tracker.scenario import paper_plant_config  # noqa: E402

CONFIG = ROOT / 'config'


@dataclass
class Row:
    """One row: measured ``values`` (``unit``), ratios to the single run, target, verdict."""

    name: str
    unit: str
    values: list = field(default_factory=list)
    ratios: list | None = None
    target: str = ''
    met: bool | None = None


def timed(fn, reps: int) -> list[float]:
    """Wall times (s) of ``reps`` calls of ``fn``."""
    out = []
    for _ in range(reps):
        t0 = time.perf_counter()
        fn()
        out.append(time.perf_counter() - t0)
    return out


def measure(quick: bool = False, reps: int = 3) -> list[Row]:
    """Measure every row (also the rows of ``benchmarks/run.py``'s batch section)."""
    reps = max(1, reps)
    gains = CONFIG / 'tracker_gains.yaml'
    K = read_gain_file(gains)
    problem = load_problem(CONFIG / 'paper_problem.yaml')
    pc = paper_plant_config()
    tc = TrackerConfig(K=K)
    jobs = default_jobs()
    rows = []
    print(f'# load average at start {os.getloadavg()[0]:.2f} ({os.cpu_count()} cores, '
          f'{jobs} usable); shared machine: figures under load', file=sys.stderr)

    single_steps = 1000 if quick else 3000

    def single_rate() -> float:
        return single_steps / timed(lambda: simulate_tracking(pc, tc, circle(), single_steps),
                                    1)[0]

    singles: list[float] = []
    rng = np.random.default_rng(0)
    batch_steps = 200 if quick else 600
    batch_rows = []
    for n in (1000, 10000):
        P = perturbation_schedule(problem.E, problem.F, sample_deltas(rng, n, 1, (2, 2)))
        cases = BatchCases(n, perturbation=P, x0=pc.x0 + rng.uniform(-0.1, 0.1, n),
                           th0=pc.th0 + rng.uniform(-0.3, 0.3, n))
        spec = StudySpec(cases=n, duration=batch_steps * pc.dt, pose_spread=(0.1, 0.3))
        path = PathBatch('circle', 0.5, 0.01)
        one, many, r_one, r_many = [], [], [], []
        for _ in range(reps):          # single run right before each: ratios under one load
            s1 = single_rate()
            singles.append(s1)
            one.append(n * batch_steps / timed(
                lambda: simulate_batch(pc, tc, circle(), batch_steps, cases, exact=False),
                1)[0])
            r_one.append(one[-1] / s1)
            if jobs > 1:
                s2 = single_rate()
                singles.append(s2)
                many.append(n * batch_steps / timed(
                    lambda: run_study(spec, pc, tc, path, problem.E, problem.F, None, jobs),
                    1)[0])
                r_many.append(many[-1] / s2)
        batch_rows.append((f'batch N = {n:,}, 1 process', 'case-steps/s', one, r_one,
                           '>= 100 x'))
        if jobs > 1:
            batch_rows.append((f'batch N = {n:,}, {jobs} processes (study)', 'case-steps/s',
                               many, r_many, '>= 100 x'))
    rows.append(('single run (simulate_tracking)', 'steps/s', singles, None, ''))
    rows.extend(batch_rows)

    n_study = 2000 if quick else 10000
    spec = StudySpec(cases=n_study, duration=60.0, latency=(0.0, 0.3), pose_spread=(0.1, 0.3))
    path = PathBatch('circle', 0.5, 0.01)
    design = read_gain_design(gains)
    tstudy = timed(lambda: run_study(spec, pc, tc, path, problem.E, problem.F, design, jobs),
                   1 if not quick else reps)
    rows.append((f'study {n_study:,} cases x 60 s, {jobs} processes', 's wall', tstudy, None,
                 '< 120 s'))
    return [Row(*r) for r in rows]


def main(argv=None) -> int:
    """Measure every row, print the table."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--quick', action='store_true', help='fewer steps, study of 2,000 cases')
    ap.add_argument('--reps', type=int, default=3, help='repetitions per row (default 3)')
    args = ap.parse_args(argv)
    rows = measure(args.quick, args.reps)
    head = (f'{"row":<44}{"median":>11} {"min-max":>25}  {"unit":<13}'
            f'{"x single (min-max)":>22}  target')
    print(head)
    print('-' * len(head))
    for name, unit, vals, ratios, target in ((r.name, r.unit, r.values, r.ratios, r.target)
                                             for r in rows):
        med = statistics.median(vals)
        spread = f'{min(vals):.3g}-{max(vals):.3g} (n={len(vals)})'
        ratio = (f'{statistics.median(ratios):.0f} x ({min(ratios):.0f}-{max(ratios):.0f})'
                 if ratios else '')
        met = ''
        if target.startswith('>='):
            met = 'MET' if ratios and statistics.median(ratios) >= 100 else 'MISSED'
        elif target.startswith('<'):
            met = 'MET' if med < 120 else 'MISSED'
        print(f'{name:<44}{med:>11.4g} {spread:>25}  {unit:<13}{ratio:>22}  {target} {met}')
    print(f'# load average at end {os.getloadavg()[0]:.2f}', file=sys.stderr)
    return 0


if __name__ == '__main__':
    sys.exit(main())
