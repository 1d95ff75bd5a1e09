#!/usr/bin/env python3
"""Batch simulation against the single run (issue 15, items 1-2).  Standalone, one table.

    .venv/bin/python benchmarks/batch.py [--quick] [--reps R]

Everything is the paper scenario (config/paper_scenario.yaml plant, config/tracker_gains.yaml
gain, the circle).  The baseline is today's single run, ``simulate_tracking`` of that
scenario (3,000 steps; 1,000 with ``--quick``), measured in this run right before and right
after every repetition of every batch row: each ratio is the batch's case-steps/s over the
mean of the two single runs around it (the machine's load moves both alike); the ratio
column gives the median and range over the repetitions.

Rows:

* ``single run``: ``simulate_tracking`` steps/s (every measurement of the run);
* ``batch N, 1 process``: ``simulate_batch(..., exact=False)`` in this process, N = 1,000
  and 10,000 cases (per-case constant Delta in the unit ball and initial pose), 600 steps
  (200 with ``--quick``): case-steps/s and ratio (target >= 100 x);
* ``study N x 60 s, J processes``: ``run_study`` (what ``nonfragile_tracker study`` runs:
  sampling, then the cases split over J worker processes - all the cores this process may
  use, 2 on the reference machine, when each gets at least
  ``study.MIN_CASES_PER_JOB`` cases, else in this process - each a ``simulate_batch``)
  of the paper scenario,
  60 s per case, Delta in the unit ball, command latency 0-0.3 s, pose spread 0.1 m /
  0.3 rad; N = 1,000 and 10,000 (2,000 with ``--quick``): case-steps/s and ratio (target
  >= 100 x) and, for the largest N, the wall time (target < 120 s for 10,000 cases).

Median over ``--reps`` repetitions (min-max beside it).  The machine is shared: the
header gives the load average; figures under load are lower than on a quiet machine.

For ``make bench``: :func:`measure` returns the rows (:class:`Row`), :func:`table` formats
them, :func:`main` does both.
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

from nonfragile_tracker.control.simulation.batch import (BatchCases, PathBatch,  # noqa: E402
                                              perturbation_schedule, sample_deltas,
                                              simulate_batch)
from nonfragile_tracker.control.simulation.gains import read_gain_design, read_gain_file  # noqa: E402
from nonfragile_tracker.control.simulation.tracker import TrackerConfig  # noqa: E402
from nonfragile_tracker.control.synthesis.problem import load_problem  # noqa: E402
from nonfragile_tracker.control.simulation.reference import circle  # noqa: E402
from nonfragile_tracker.control.simulation.simulate import simulate_tracking  # noqa: E402
from nonfragile_tracker.control.simulation.study import StudySpec, default_jobs, run_study  # noqa: E402
from nonfragile_tracker.interface.scenario import paper_plant_config  # noqa: E402

CONFIG = ROOT / 'config'
#: Target of the batch rows: case-steps/s over the single run's steps/s.
RATIO_TARGET = 100.0
#: Target of the 10,000-case study: wall time (s).
STUDY_TARGET_S = 120.0


@dataclass
class Row:
    """One row: measured ``values`` (``unit``), ratios to the single run, target, verdict."""

    name: str
    unit: str
    values: list = field(default_factory=list)
    ratios: list | None = None
    target: str = ''
    met: bool | None = None


def _timed(fn) -> float:
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def measure(quick: bool = False, reps: int = 3, jobs: int | None = None) -> list[Row]:
    """Measure every row (see the module docstring); ``jobs`` defaults to the usable cores."""
    reps = max(1, int(reps))
    jobs = default_jobs() if jobs is None else int(jobs)
    gains = CONFIG / 'tracker_gains.yaml'
    K = read_gain_file(gains)
    design = read_gain_design(gains)
    problem = load_problem(CONFIG / 'paper_problem.yaml')
    pc = paper_plant_config()
    tc = TrackerConfig(K=K)
    path = PathBatch('circle', 0.5, 0.01)
    single_steps = 1000 if quick else 3000
    single = Row('single run (simulate_tracking)', 'steps/s')

    def single_rate() -> float:
        rate = single_steps / _timed(lambda: simulate_tracking(pc, tc, circle(), single_steps))
        single.values.append(rate)
        return rate

    def against_single(row: Row, case_steps: int, fn) -> float:
        before = single_rate()
        wall = _timed(fn)
        after = single_rate()
        row.values.append(case_steps / wall)
        row.ratios.append(case_steps / wall / (0.5 * (before + after)))
        return wall

    rows = [single]
    rng = np.random.default_rng(0)
    batch_steps = 200 if quick else 600
    for n in (1000, 10000):
        P = perturbation_schedule(problem.E, problem.F, sample_deltas(rng, n, 1, (2, 2)))
        cases = BatchCases(n, perturbation=P, x0=pc.x0 + rng.uniform(-0.1, 0.1, n),
                           th0=pc.th0 + rng.uniform(-0.3, 0.3, n))
        row = Row(f'batch N = {n:,}, 1 process', 'case-steps/s', ratios=[],
                  target=f'>= {RATIO_TARGET:.0f} x')
        for _ in range(reps):
            against_single(row, n * batch_steps, lambda: simulate_batch(
                pc, tc, circle(), batch_steps, cases, exact=False))
        rows.append(row)

    study_sizes = (1000, 2000) if quick else (1000, 10000)
    for n in study_sizes:
        spec = StudySpec(cases=n, duration=60.0, latency=(0.0, 0.3), pose_spread=(0.1, 0.3))
        used = []
        row = Row('', 'case-steps/s', ratios=[], target=f'>= {RATIO_TARGET:.0f} x')
        walls = [against_single(row, n * 6000, lambda: used.append(run_study(
            spec, pc, tc, path, problem.E, problem.F, design, jobs).jobs)) for _ in range(reps)]
        row.name = f'study {n:,} x 60 s, {used[0]} process{"es" if used[0] > 1 else ""}'
        rows.append(row)
        if n == study_sizes[-1]:
            rows.append(Row(row.name, 's wall', walls, target=f'< {STUDY_TARGET_S:.0f} s'))
    for row in rows:
        if row.ratios:
            row.met = statistics.median(row.ratios) >= RATIO_TARGET
        elif row.target.startswith('<'):
            row.met = statistics.median(row.values) < STUDY_TARGET_S
    return rows


def table(rows: list[Row]) -> str:
    """The rows as a text table (median, min-max, ratio median and range, target, verdict)."""
    head = (f'{"row":<38}{"median":>11} {"min-max":>25}  {"unit":<13}'
            f'{"x single (min-max)":>20}  target')
    lines = [head, '-' * len(head)]
    for r in rows:
        med = statistics.median(r.values)
        spread = f'{min(r.values):.3g}-{max(r.values):.3g} (n={len(r.values)})'
        ratio = (f'{statistics.median(r.ratios):.0f} x ({min(r.ratios):.0f}-'
                 f'{max(r.ratios):.0f})' if r.ratios else '')
        verdict = '' if r.met is None else ('MET' if r.met else 'MISSED')
        lines.append(f'{r.name:<38}{med:>11.4g} {spread:>25}  {r.unit:<13}{ratio:>20}  '
                     f'{r.target} {verdict}'.rstrip())
    return '\n'.join(lines)


def main(argv=None) -> int:
    """Measure every row, print the table."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--quick', action='store_true',
                    help='shorter batch rows, the study at 2,000 cases')
    ap.add_argument('--reps', type=int, default=3, help='repetitions per row (default 3)')
    args = ap.parse_args(argv)
    jobs = default_jobs()
    print(f'# load average at start {os.getloadavg()[0]:.2f} ({os.cpu_count()} cores, '
          f'{jobs} usable); shared machine: figures under load.  "1 process": '
          f'simulate_batch in this process; "{jobs} processes": the study splits the cases '
          f'over {jobs} worker processes', file=sys.stderr)
    print(table(measure(args.quick, args.reps, jobs)))
    print(f'# load average at end {os.getloadavg()[0]:.2f}', file=sys.stderr)
    return 0


if __name__ == '__main__':
    sys.exit(main())
