"""Benchmark section 2, delay loop: rightmost roots against a reference discretization.

Run through ``benchmarks/run.py --only delay``; helpers come from ``harness``.
"""
from __future__ import annotations

import json
import os

from harness import (
    CONFIG,
    Table,
    fmt,
    log,
    run_worker,
    spread,
    timeit,
)


def worker_roots(reps: int) -> None:
    """Child: rightmost_roots timing (run with OPENBLAS_NUM_THREADS=1 for the comparison)."""
    import numpy as np
    import yaml
    from nonfragile_tracker.control.synthesis import delay
    from nonfragile_tracker.control.synthesis.problem import load_problem
    p = load_problem(CONFIG / 'paper_problem.yaml')
    K = np.array(yaml.safe_load((CONFIG / 'paper_gains.yaml').read_text())['K_nf'], float)
    A0 = delay.closed_loop_matrix(p.A, p.B, K)
    delay.rightmost_roots(A0, p.A_tau, p.tau)
    s, _ = timeit(lambda: delay.rightmost_roots(A0, p.A_tau, p.tau), reps)
    print(json.dumps(s))


# ============================================================================ 2. delay loop

def _cheb(N: int):
    import numpy as np
    x = np.cos(np.pi * np.arange(N + 1) / N)
    c = np.hstack([2.0, np.ones(N - 1), 2.0]) * (-1.0) ** np.arange(N + 1)
    X = np.tile(x, (N + 1, 1)).T
    dX = X - X.T
    D = np.outer(c, 1.0 / c) / (dX + np.eye(N + 1))
    return D - np.diag(D.sum(axis=1))


def reference_roots(A0, A1, tau: float, N: int = 160, keep: int = 12):
    """Independent reference: own Chebyshev discretization of the generator at high N,
    then Newton on det T(s) (f'/f = tr(T^-1 T')) to |ds| <= 1e-15 |s|."""
    import numpy as np
    n = A0.shape[0]
    M = np.kron(_cheb(N) * (2.0 / tau), np.eye(n))
    M[:n, :] = 0.0
    M[:n, :n] = A0
    M[:n, -n:] += A1
    ev = np.linalg.eigvals(M)
    ev = ev[np.abs(ev) < 0.5 * N / tau]          # the well-resolved part of the spectrum
    ev = ev[np.argsort(-ev.real)][:keep]
    I = np.eye(n)
    out = []
    for s in ev:
        s = complex(s)
        for _ in range(100):
            E = np.exp(-s * tau)
            T = s * I - A0 - A1 * E
            dT = I + tau * E * A1
            try:
                step = 1.0 / np.trace(np.linalg.solve(T, dT))
            except np.linalg.LinAlgError:      # landed exactly on the root
                break
            s -= step
            if abs(step) <= 1e-15 * max(1.0, abs(s)):
                break
        T = s * I - A0 - A1 * np.exp(-s * tau)
        res = np.linalg.svd(T, compute_uv=False)[-1]
        if not any(abs(s - u) < 1e-9 * max(1.0, abs(s)) for u, _ in out):
            out.append((s, float(res)))
    out.sort(key=lambda t: (-t[0].real, -t[0].imag))
    return out


def bench_delay(cfg, table: Table, raw: dict) -> None:
    import numpy as np
    import yaml
    from nonfragile_tracker.control.synthesis import delay
    from nonfragile_tracker.control.synthesis.problem import load_problem

    p = load_problem(CONFIG / 'paper_problem.yaml')
    gains = yaml.safe_load((CONFIG / 'paper_gains.yaml').read_text())
    K = np.array(gains['K_nf'], float)
    loops = {'D=0': delay.closed_loop_matrix(p.A, p.B, K)}
    for name, D in p.perturbations.items():
        loops[name] = delay.closed_loop_matrix(p.A, p.B, K, p.E, p.F, D)
    res: dict = {'loops': {}}
    raw['delay'] = res
    log('delay loop: rightmost_roots / spectral_abscissa timing and accuracy')
    A0 = loops['D=0']
    delay.rightmost_roots(A0, p.A_tau, p.tau)         # first call (lru caches)
    rr_s, rr = timeit(lambda: delay.rightmost_roots(A0, p.A_tau, p.tau), cfg.roots_reps)
    sa_s, _ = timeit(lambda: delay.spectral_abscissa(A0, p.A_tau, p.tau), cfg.roots_reps)
    ref_s, _ = timeit(lambda: reference_roots(A0, p.A_tau, p.tau), max(1, cfg.roots_reps // 5))
    one, _, _ = run_worker(['roots', str(cfg.roots_reps)], timeout=120,
                           env=dict(os.environ, OPENBLAS_NUM_THREADS='1'))
    res['rightmost_roots_openblas1_s'] = one
    res.update(rightmost_roots_s=rr_s, spectral_abscissa_s=sa_s, reference_s=ref_s,
               N=int(rr[-1].N), converged=bool(rr[-1].converged))
    worst_abs, worst_root = 0.0, 0.0
    for name, M in loops.items():
        got = delay.rightmost_roots(M, p.A_tau, p.tau)
        ref = reference_roots(M, p.A_tau, p.tau)
        ref_abs = max(s.real for s, _ in ref)
        d_abs = abs(got.abscissa - ref_abs)
        d_roots = max(min(abs(complex(z) - s) for s, _ in ref) for z in got.roots)
        missing = [s for s, _ in ref if s.real >= got.roots[-1].real - 1e-9
                   and min(abs(complex(z) - s) for z in got.roots) > 1e-6]
        res['loops'][name] = {
            'abscissa': float(got.abscissa), 'reference_abscissa': float(ref_abs),
            'abscissa_diff': float(d_abs), 'max_root_diff': float(d_roots),
            'roots': [[z.real, z.imag] for z in map(complex, got.roots)],
            'reference_roots': [[s.real, s.imag, r] for s, r in ref[:8]],
            'missing_in_window': [[s.real, s.imag] for s in missing],
            'N': int(got.N), 'converged': bool(got.converged)}
        worst_abs = max(worst_abs, d_abs)
        worst_root = max(worst_root, d_roots)
    res['worst_abscissa_diff'] = worst_abs
    res['worst_root_diff'] = worst_root
    nmiss = sum(len(v['missing_in_window']) for v in res['loops'].values())
    table.add('2.1', 'rightmost_roots (6 roots), paper loop with K_nf', rr_s['median'] * 1e3,
              'ms', spread(rr_s, 1e3) + f"; N={res['N']}, converged {fmt(res['converged'])}",
              f"x{fmt(ref_s['median'] / rr_s['median'])} faster than ref (N=160 + Newton)")
    if one:
        table.add('2.1b', '  same, OPENBLAS_NUM_THREADS=1 (new process)', one['median'] * 1e3,
                  'ms', spread(one, 1e3),
                  f"x{fmt(rr_s['median'] / one['median'])} faster than default threads")
    table.add('2.2', 'spectral_abscissa, same loop', sa_s['median'] * 1e3, 'ms',
              spread(sa_s, 1e3) + f"; abscissa {fmt(res['loops']['D=0']['abscissa'], 6)}")
    table.add('2.3', 'abscissa error vs reference (worst of D=0, Delta_1/2)',
              worst_abs, '1/s', f"max root distance {fmt(worst_root)}; {nmiss} reference "
              'roots missing in the returned window')
