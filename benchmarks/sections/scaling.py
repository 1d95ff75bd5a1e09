"""Benchmark section 1.s (issue 15): Theorem 1 at n = 16 and 32, cold problem, warm process.

The figures come from ``benchmarks/synthesis_scaling.py`` (its ``measure``: a child
process per solve, certificate verified); ``benchmarks/run.py --only scaling``.
"""
from __future__ import annotations

from harness import Table, elapsed, fmt, log, summary

#: Issue 15's figures for the stacked problem before the work (1.gN CLARABEL rows).
ISSUE_REF = {16: 1.9, 32: 76.0}


def bench_scaling(cfg, table: Table, raw: dict) -> None:
    import synthesis_scaling              # benchmarks/synthesis_scaling.py
    res: dict = {}
    raw['scaling'] = res
    for n, *kind_reps in cfg.scaling:
        for kind, reps in zip(('stacked', 'coupled'), kind_reps):
            limit = cfg.scaling_timeout
            if n > 16:                     # the long tail: cut to the time budget
                limit = max(30.0, min(limit, cfg.budget - elapsed() - 300))
            log(f'synthesis scaling: {kind} n={n} x{reps} (timeout {limit:.0f} s)')
            cols = synthesis_scaling.measure(n, kind, reps, False, limit)
            col = cols['today']
            res[f'{kind}{n}'] = {'today': col, 'timeout_s': limit}
            rid = f"1.s{n}{kind[0]}"
            fig = (f'Theorem 1 n={n} {kind}' + (' (n/4 robots)' if kind == 'stacked' else
                                                 ' (+0.02 dense coupling)') +
                   ', cold problem, warm process')
            target = 'synthesis_n16' if n <= 16 else 'synthesis_n32'
            if 'wall' not in col:
                why = (f"> {fmt(col['timeout'])} s (timeout)" if 'timeout' in col
                       else f"failed: {col.get('error', '?')}"[:120])
                table.add(rid, fig, None, 's', why, target=target)
                continue
            s = summary(col['walls'])
            how = ('blocks ' + 'x'.join(map(str, col['blocks'])) if col.get('blocks')
                   else 'one LMI')
            detail = (f"{fmt(s['min'])}-{fmt(s['max'])} (n={s['n']}); " if s['n'] > 1
                      else 'n=1; ') + (f"solver {fmt(col['solver'])} s; {how}; certificate "
                                       f"{'verified' if col['ok'] else 'NOT verified'}")
            if kind == 'stacked':
                ratio = (f"x{fmt(ISSUE_REF[n] / col['wall'])} faster than issue ref "
                         f"{fmt(ISSUE_REF[n])} s" if n in ISSUE_REF else '')
            else:
                st = res.get(f'stacked{n}', {}).get('today', {})
                ratio = f"x{fmt(col['wall'] / st['wall'])} stacked" if 'wall' in st else ''
            table.add(rid, fig, col['wall'], 's', detail, ratio, target=target,
                      also=bool(col['ok']), also_text='certificate verified')
