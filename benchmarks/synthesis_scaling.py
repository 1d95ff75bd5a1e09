#!/usr/bin/env python3
"""Theorem 1 synthesis time against n: one table, ratios side by side.

Standalone: ``.venv/bin/python benchmarks/synthesis_scaling.py [--sizes 8,16,32]
[--reps 3] [--no-baseline]``.

For each n two problems, each timed cold (new shape) in a warm process (a child process
per measurement that first solves the paper's problem, so imports and cvxpy's first-use
cost are paid before the clock starts):

* stacked: n/4 copies of the paper's robot, block-diagonal (the ``1.gN`` rows of
  ``benchmarks/run.py``), gain bound 8.67;
* coupled: the same plus 0.02 x a seeded Gaussian matrix added to A (no block structure).

Columns: today's path (``synthesize`` defaults: block decoupling; for n >= 8 the reduced
LMI of size n + rank(A_tau) + rank(F), compiled without DPP on its first solve) and the
previous single paper-form solve (``decouple=False`` and the reduced form disabled),
median over ``--reps`` children; every certificate is verified by
``verify_certificate`` (the ``ok`` column).  Timings are single-threaded
(OPENBLAS_NUM_THREADS=1; Clarabel's own threads are its default).  n = 32 with the
previous path takes minutes.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

CHILD = r'''
import json, sys, time, warnings
sys.path.insert(0, sys.argv[1])
warnings.simplefilter('ignore')
import numpy as np, scipy.linalg as sla
from nonfragile_tracker.control.synthesis import lmi
from nonfragile_tracker.control.synthesis.problem import load_problem
n, kind, path = int(sys.argv[2]), sys.argv[3], sys.argv[4]
p0 = load_problem(sys.argv[1] + '/config/paper_problem.yaml')
lmi.synthesize(p0, gain_bound=8.67)                 # warm process
bd = lambda M: sla.block_diag(*([M] * (n // 4)))
p = p0.replace(A=bd(p0.A), B=bd(p0.B), A_tau=bd(p0.A_tau), E=bd(p0.E), F=bd(p0.F),
               perturbations={}, name=f'{kind}{n}')
if kind == 'coupled':
    p = p.replace(A=p.A + 0.02 * np.random.default_rng(0).standard_normal((n, n)))
kw = {}
if path == 'previous':
    lmi.COMPACT_FROM_N = 10 ** 9
    kw['decouple'] = False
t = time.perf_counter()
r = lmi.synthesize(p, gain_bound=8.67, **kw)
wall = time.perf_counter() - t
ok = lmi.verify_certificate(p, r.K, r.P, r.Q, r.eps).ok
print(json.dumps({'wall': wall, 'solver': r.solve_time, 'ok': bool(ok),
                  'blocks': r.extra.get('blocks'), 'norm': float(np.linalg.norm(r.K, 2))}))
'''


def run(n: int, kind: str, path: str, timeout: float) -> dict | None:
    env = dict(os.environ, OPENBLAS_NUM_THREADS='1')
    try:
        out = subprocess.run([sys.executable, '-c', CHILD, str(ROOT), str(n), kind, path],
                             capture_output=True, text=True, timeout=timeout, env=env)
    except subprocess.TimeoutExpired:
        return {'timeout': timeout}
    if out.returncode != 0:
        return {'error': (out.stderr.strip().splitlines() or ['?'])[-1]}
    return json.loads(out.stdout.strip().splitlines()[-1])


def measure(n: int, kind: str, reps: int, baseline: bool, timeout: float) -> dict:
    """One problem (``kind`` 'stacked' or 'coupled', n states): ``{'today': col,
    'previous': col}`` (``previous`` only with ``baseline``), col = medians of 'wall' and
    'solver' (s), 'ok' (every certificate verified), 'blocks', 'walls' (each run), or the
    first run's ``{'timeout': s}`` / ``{'error': text}`` if none finished (also the rows
    of ``benchmarks/run.py``'s scaling section)."""
    cols = {}
    for path in ('today', 'previous'):
        if path == 'previous' and not baseline:
            continue
        k = reps if path == 'today' or n < 32 else 1
        runs = [run(n, kind, path, timeout) for _ in range(k)]
        good = [r for r in runs if r and 'wall' in r]
        if not good:
            cols[path] = runs[0]
            continue
        cols[path] = {'wall': statistics.median(r['wall'] for r in good),
                      'solver': statistics.median(r['solver'] for r in good),
                      'ok': all(r['ok'] for r in good), 'blocks': good[0]['blocks'],
                      'walls': [r['wall'] for r in good]}
    return cols


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--sizes', default='8,16,32')
    ap.add_argument('--reps', type=int, default=3)
    ap.add_argument('--no-baseline', action='store_true', help='skip the previous path')
    ap.add_argument('--timeout', type=float, default=600.0)
    args = ap.parse_args(argv)
    sizes = [int(x) for x in args.sizes.split(',')]
    print('# Theorem 1 (non-fragile, ||K|| <= 8.67), cold problem in a warm process, '
          f'median of {args.reps}, OPENBLAS_NUM_THREADS=1')
    print(f'{"problem":12s} {"n":>3s} {"today s":>8s} {"solver s":>8s} {"ok":>3s} '
          f'{"previous s":>10s} {"solver s":>8s} {"ok":>3s} {"speed-up":>8s}  path today')
    for n in sizes:
        for kind in ('stacked', 'coupled'):
            cols = measure(n, kind, args.reps, not args.no_baseline, args.timeout)
            t, b = cols.get('today', {}), cols.get('previous', {})

            def cell(c: dict, key: str, width: int) -> str:
                if 'wall' not in c:
                    what = 'n/a' if not c else ('>' + f"{c['timeout']:.0f}" if 'timeout' in c
                                                else 'error')
                    return f'{what:>{width}s}'
                return f'{c[key]:{width}.3f}'
            ratio = (f"x{b['wall'] / t['wall']:.1f}" if 'wall' in t and 'wall' in b
                     else 'n/a')
            how = ('blocks ' + 'x'.join(map(str, t['blocks'])) if t.get('blocks')
                   else ('reduced LMI' if n >= 8 else 'paper LMI'))
            ok_t = 'yes' if t.get('ok') else 'NO'
            ok_b = 'yes' if b.get('ok') else ('NO' if 'wall' in b else '-')
            print(f'{kind:12s} {n:3d} {cell(t, "wall", 8)} {cell(t, "solver", 8)} {ok_t:>3s} '
                  f'{cell(b, "wall", 10)} {cell(b, "solver", 8)} {ok_b:>3s} {ratio:>8s}  '
                  f'{how}', flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
