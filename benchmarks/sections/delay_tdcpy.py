"""Benchmark section 2.4 (issue 15): spectral abscissa against tdcpy, case by case.

The figures come from ``benchmarks/delay_analysis.py`` (its ``measure``), run in a child
process with ``OPENBLAS_NUM_THREADS=1`` as the standalone command runs; tdcpy runs in its
own environment (``$TDCPY_PYTHON`` or ``benchmarks/tdcpy-venv/bin/python``, made by
``make bench-env``).  ``benchmarks/run.py --only tdcpy``.
"""
from __future__ import annotations

import json
import math
import os

from harness import Table, fmt, log, run_worker, spread, summary

#: Both abscissa errors below this (about 1e3 machine epsilons) count as equal accuracy:
#: the reference itself is only that good.
ROUND_OFF = 1e-13


def worker_tdcpy(reps: int) -> None:
    """Child: the rows of ``benchmarks/delay_analysis.py`` as one JSON line."""
    import delay_analysis                 # benchmarks/delay_analysis.py
    python = delay_analysis.default_tdcpy_python()
    rows, note = delay_analysis.measure(reps, python)
    print(json.dumps({'rows': rows, 'note': note, 'tdcpy_python_given': 'TDCPY_PYTHON' in
                      os.environ}))


def bench_tdcpy(cfg, table: Table, raw: dict) -> None:
    log(f'delay analysis against tdcpy ({cfg.tdcpy_reps} reps per case)')
    out, wall, timed_out = run_worker(['tdcpy', str(cfg.tdcpy_reps)], timeout=900,
                                      env=dict(os.environ, OPENBLAS_NUM_THREADS='1'))
    raw['tdcpy'] = {'result': out, 'process_wall_s': wall, 'timed_out': timed_out,
                    'round_off': ROUND_OFF}
    if not out:
        table.note('2.4', 'delay analysis against tdcpy', 'timed out' if timed_out
                   else 'failed (see stderr)')
        return
    have = any(r[7] for r in out['rows'])
    if not have:
        table.note('2.4', 'tdcpy not available: ours only', out['note'][:200] +
                   ' - make bench-env installs it (PyPI tdcpy==0.0.1)')
    for k, (name, n, tau, N, warm, cold, err, tdc, ref, warms, colds) in enumerate(out['rows']):
        w = summary(warms)
        c = summary(colds)
        detail = (f"{spread(w, 1e3)}; cold {fmt(c['median'] * 1e3)} ms; N={N}; error "
                  f"ours {fmt(err)}")
        if tdc:
            t_err = abs(tdc[0] - ref)
            detail += f', tdcpy {fmt(t_err)}'
            accurate = err <= t_err or err <= ROUND_OFF
            table.add(f'2.4.{k + 1}', f'spectral_abscissa {name} (n={n})', w['median'] * 1e3,
                      'ms', detail, f"tdcpy {fmt(tdc[1] * 1e3)} ms, x{fmt(tdc[1] / w['median'])}"
                      ' faster', target='tdcpy_peer', check=w['median'] / tdc[1],
                      also=accurate, also_text='error <= tdcpy', raw={'warm_s': warms,
                      'cold_s': colds, 'tdcpy_s': tdc[1], 'error': err, 'tdcpy_error': t_err,
                      'reference': ref})
        else:
            table.add(f'2.4.{k + 1}', f'spectral_abscissa {name} (n={n})', w['median'] * 1e3,
                      'ms', detail, 'tdcpy n/a', target='tdcpy_peer', check=math.nan,
                      raw={'warm_s': warms, 'cold_s': colds, 'error': err, 'reference': ref})
