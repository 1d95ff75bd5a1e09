"""Benchmark section 3.2-3.7 (issue 15): batch simulation and the robustness study.

The figures come from ``benchmarks/batch.py`` (its ``measure``), run in a child process
with ``OPENBLAS_NUM_THREADS=1`` as the standalone command runs; ``benchmarks/run.py
--only batch``.
"""
from __future__ import annotations

import json
import os

from harness import Table, fmt, log, run_worker, summary


def worker_batch(quick: bool, reps: int) -> None:
    """Child: the rows of ``benchmarks/batch.py`` (``measure(quick, reps)`` -> ``Row``s with
    name, unit, values, ratios, target, met) as one JSON line."""
    import dataclasses

    import batch                          # benchmarks/batch.py (run.py puts benchmarks/ first)
    rows = [dataclasses.asdict(r) for r in batch.measure(quick, reps)]
    print(json.dumps({'rows': rows, 'jobs': os.cpu_count()}))


def bench_batch(cfg, table: Table, raw: dict) -> None:
    log(f'batch: single run, batch N = 1,000 / 10,000 (x{cfg.batch_reps}), study')
    out, wall, timed_out = run_worker(['batch', '1' if cfg.quick else '0', str(cfg.batch_reps)],
                                      timeout=600, env=dict(os.environ, OPENBLAS_NUM_THREADS='1'))
    raw['batch'] = {'result': out, 'process_wall_s': wall, 'timed_out': timed_out}
    if not out:
        table.note('3.2', 'batch section', 'timed out' if timed_out else 'failed (see stderr)')
        return
    rid = 2
    for row in out['rows']:
        name, unit, vals, ratios = row['name'], row['unit'], row['values'], row['ratios']
        s = summary(vals)
        detail = f"{fmt(s['min'])}-{fmt(s['max'])} (n={s['n']})" if s['n'] > 1 else 'n=1'
        if ratios:
            r = summary(ratios)
            ratio = f"x{fmt(r['median'])} single run (same load)" + (
                f" ({fmt(r['min'])}-{fmt(r['max'])})" if r['n'] > 1 else '')
            table.add(f'3.{rid}', name, s['median'], unit, detail, ratio,
                      target='batch_speedup', check=r['median'], raw={'values': vals,
                                                                       'ratios': ratios})
        elif row['target'].startswith('<'):
            table.add(f'3.{rid}', f'{name}: wall time', s['median'], 's', detail, '',
                      target='study_10k' if '10,000' in name else None, raw={'values': vals})
        else:
            table.add(f'3.{rid}', name, s['median'], unit, detail,
                      'the baseline of the batch ratios', raw={'values': vals})
        rid += 1
