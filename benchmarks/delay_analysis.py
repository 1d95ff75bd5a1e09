#!/usr/bin/env python3
"""Spectral abscissa of x' = A0 x + A1 x(t - tau): ours against tdcpy, one table.

Standalone: ``.venv/bin/python benchmarks/delay_analysis.py [--reps 7]``.

Cases (issue 15, item 3): the paper loop (config/paper_problem.yaml, K_nf of
config/paper_gains.yaml) with Delta in {0, -I, +I}; seeded random stable systems with
n = 10 and n = 32, tau = 1; a 2-state loop with tau = 5.

* ours, warm: median time of ``delay.spectral_abscissa`` over ``--reps`` repeated calls
  (the module remembers the degree N and Arnoldi size k per shape, as in margin and
  worst-case searches); ours, cold: the same with those caches cleared before each call.
* tdcpy: ``tdcpy.spectral_abscissa(RDDE)`` (PyPI ``tdcpy==0.0.1``), run by the python of
  its own environment (``--tdcpy-python``, default ``$TDCPY_PYTHON`` or
  ``benchmarks/tdcpy-venv/bin/python``, made with ``python3 -m venv benchmarks/tdcpy-venv &&
  benchmarks/tdcpy-venv/bin/pip install tdcpy==0.0.1``; never installed in the project venv).  If it
  is absent the table says so and shows ours only.
* error: |abscissa - reference|, the reference being an independent high-degree
  discretization (sparse shift-invert at N_ref = min(max(64, 3 R tau), 160)) refined by Newton's
  method on det T(s) (step f/f' = 1 / tr(T^-1 T')) to |step| <= 1e-15 |s|.
Timings are single-threaded (OPENBLAS_NUM_THREADS=1 is set before numpy loads).
"""
from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path

os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

TDCPY_SCRIPT = r'''
import json, sys, time, warnings
import numpy as np
import tdcpy
warnings.simplefilter('ignore')
cases, reps = json.load(sys.stdin)
out = {}
for name, (A0, A1, tau) in cases.items():
    A = np.stack([np.array(A0), np.array(A1)], axis=2)
    sys_ = tdcpy.RDDE(A=A, hA=np.array([0.0, tau]))
    val = tdcpy.spectral_abscissa(sys_)
    ts = []
    for _ in range(reps):
        t = time.perf_counter()
        val = tdcpy.spectral_abscissa(sys_)
        ts.append(time.perf_counter() - t)
    out[name] = [float(val), float(np.median(ts))]
print(json.dumps(out))
'''


def cases() -> dict:
    import yaml
    from nonfragile_tracker.control.synthesis import delay
    from nonfragile_tracker.control.synthesis.problem import load_problem

    p = load_problem(ROOT / 'config' / 'paper_problem.yaml')
    K = np.array(yaml.safe_load((ROOT / 'config' / 'paper_gains.yaml').read_text())['K_nf'],
                 float)
    q, r = p.E.shape[1], p.F.shape[0]
    out = {'paper, Delta=0': (delay.closed_loop_matrix(p.A, p.B, K), p.A_tau, p.tau),
           'paper, Delta=-I': (delay.closed_loop_matrix(p.A, p.B, K, p.E, p.F, -np.eye(q, r)),
                               p.A_tau, p.tau),
           'paper, Delta=+I': (delay.closed_loop_matrix(p.A, p.B, K, p.E, p.F, np.eye(q, r)),
                               p.A_tau, p.tau)}
    for n, seed in ((10, 1), (32, 2)):
        out[f'random n={n}, tau=1'] = random_stable(n, seed) + (1.0,)
    out['2-state, tau=5'] = (np.array([[0.0, 1.0], [-1.0, -0.5]]),
                             np.array([[0.0, 0.0], [-0.1, -0.1]]), 5.0)
    rng = np.random.default_rng(4)           # stiff: fast stable modes, tau ||A0|| ~ 1e3
    S = np.eye(6) + 0.3 * rng.standard_normal((6, 6))
    J = np.zeros((6, 6))
    J[:2, :2] = [[-0.4, 2.0], [-2.0, -0.4]]
    J[2:, 2:] = np.diag([-40.0, -80.0, -120.0, -200.0])
    out['stiff n=6, tau=1'] = (S @ J @ np.linalg.inv(S), 0.3 * rng.standard_normal((6, 6)), 1.0)
    return out


def random_stable(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A0 = G/sqrt(n) - 1.5 I, A1 = 0.5 G'/sqrt(n) (G, G' standard normal): stable for
    every delay when ||A1|| < -max Re eig-ish; the seeds used are checked stable at tau=1."""
    rng = np.random.default_rng(seed)
    A0 = rng.standard_normal((n, n)) / math.sqrt(n) - 1.5 * np.eye(n)
    A1 = 0.5 * rng.standard_normal((n, n)) / math.sqrt(n)
    return A0, A1


def _cheb(N: int) -> np.ndarray:
    x = np.cos(np.pi * np.arange(N + 1) / N)
    c = np.hstack([2.0, np.ones(N - 1), 2.0]) * (-1.0) ** np.arange(N + 1)
    dx = x[:, None] - x[None, :]
    D = np.outer(c, 1.0 / c) / (dx + np.eye(N + 1))
    return D - np.diag(D.sum(axis=1))


def reference_abscissa(A0, A1, tau: float) -> float:
    """Independent reference (see the module docstring)."""
    import scipy.sparse as sp
    from scipy.sparse.linalg import eigs
    n = A0.shape[0]
    R = np.linalg.norm(A0, 2) + np.linalg.norm(A1, 2)
    N = int(min(max(64, 3 * R * tau), 160))
    M = sp.kron(sp.csr_matrix(_cheb(N) * (2.0 / tau)), sp.identity(n), format='lil')
    M[:n, :] = 0.0
    M[:n, :n] = A0
    M[:n, N * n:] = A1
    M = M.tocsc()
    k = min(M.shape[0] - 2, 4 * n + 40)
    ev = eigs(M, k=k, sigma=0.0, return_eigenvectors=False) if M.shape[0] > 400 else \
        np.linalg.eigvals(M.toarray())
    ev = ev[np.abs(ev) < 0.5 * N / tau]
    ev = ev[np.argsort(-ev.real)][:8]
    I = np.eye(n)
    best = -math.inf
    for s in ev:
        s = complex(s)
        for _ in range(100):
            E = np.exp(-s * tau)
            T = s * I - A0 - A1 * E
            try:
                step = 1.0 / np.trace(np.linalg.solve(T, I + tau * E * A1))
            except np.linalg.LinAlgError:
                break
            s -= step
            if abs(step) <= 1e-15 * max(1.0, abs(s)):
                break
        best = max(best, s.real)
    return best


def run_tdcpy(python: str, data: dict, reps: int) -> tuple[dict | None, str]:
    if not Path(python).exists():
        return None, f'tdcpy: interpreter {python} not found'
    payload = {k: [a.tolist(), b.tolist(), t] for k, (a, b, t) in data.items()}
    try:
        proc = subprocess.run([python, '-c', TDCPY_SCRIPT], input=json.dumps([payload, reps]),
                              capture_output=True, text=True, timeout=900,
                              env=dict(os.environ, OPENBLAS_NUM_THREADS='1'))
    except (OSError, subprocess.TimeoutExpired) as exc:
        return None, f'tdcpy: could not run ({exc})'
    if proc.returncode != 0:
        last = (proc.stderr.strip().splitlines() or ['?'])[-1]
        return None, f'tdcpy: not usable with {python} ({last})'
    return json.loads(proc.stdout.strip().splitlines()[-1]), f'tdcpy 0.0.1 via {python}'


def default_tdcpy_python() -> str:
    """``$TDCPY_PYTHON`` or ``benchmarks/tdcpy-venv/bin/python``."""
    return os.environ.get(
        'TDCPY_PYTHON', str(Path(__file__).resolve().parent / 'tdcpy-venv' / 'bin' / 'python'))


def measure(reps: int, tdcpy_python: str) -> tuple[list[tuple], str]:
    """Every case: ``(name, n, tau, N, ours warm s, ours cold s, ours error, tdcpy
    [abscissa, s] or None, reference abscissa, warm times, cold times)`` and the tdcpy note
    (also the rows of ``benchmarks/run.py``'s tdcpy section)."""
    from nonfragile_tracker.control.synthesis import delay
    data = cases()
    tdc, note = run_tdcpy(tdcpy_python, data, reps)
    rows = []
    for name, (A0, A1, tau) in data.items():
        ref = reference_abscissa(A0, A1, tau)
        val = delay.spectral_abscissa(A0, A1, tau)            # first call (imports, caches)
        warm = []
        for _ in range(reps):
            t = time.perf_counter()
            val = delay.spectral_abscissa(A0, A1, tau)
            warm.append(time.perf_counter() - t)
        cold = []
        for _ in range(reps):
            delay.clear_caches()
            t = time.perf_counter()
            delay.spectral_abscissa(A0, A1, tau)
            cold.append(time.perf_counter() - t)
        N = delay.rightmost_roots(A0, A1, tau, count=2).N
        rows.append((name, A0.shape[0], tau, N, float(np.median(warm)), float(np.median(cold)),
                     abs(val - ref), tdc.get(name) if tdc else None, ref, warm, cold))
    return rows, note


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--reps', type=int, default=7)
    ap.add_argument('--tdcpy-python', default=default_tdcpy_python())
    args = ap.parse_args(argv)
    rows, note = measure(args.reps, args.tdcpy_python)
    print(f'# delay analysis: time per spectral abscissa (median of {args.reps}), '
          f'OPENBLAS_NUM_THREADS={os.environ["OPENBLAS_NUM_THREADS"]}; {note}')
    print(f'{"case":22s} {"n":>3s} {"tau":>4s} {"N":>4s} {"ours ms":>8s} {"cold ms":>8s} '
          f'{"tdcpy ms":>9s} {"tdcpy/ours":>10s} {"ours err":>9s} {"tdcpy err":>9s}')
    for name, n, tau, N, w, c, err, t, ref, *_ in rows:
        if t is None:
            tt = ratio = terr = 'n/a'
        else:
            tt, ratio, terr = f'{t[1] * 1e3:.2f}', f'x{t[1] / w:.1f}', f'{abs(t[0] - ref):.1e}'
        print(f'{name:22s} {n:3d} {tau:4g} {N:4d} {w * 1e3:8.2f} {c * 1e3:8.2f} {tt:>9s} '
              f'{ratio:>10s} {err:9.1e} {terr:>9s}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
