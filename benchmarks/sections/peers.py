"""Benchmark section: P. Ours beside the trackers users run (issue 38; ``benchmarks/peers.py``).

The table driver's runs (quick: 50 Hz, the figure eight and the line-arc lap; full: every
trajectory at 50 and 20 Hz), every controller through the one adapter on the realistic base;
one row per controller and trajectory (50 Hz: RMS after 10 s at 0 ms, the other latencies in
the detail) and the issue's two targets: ours after bring-up at or below the best peer on
every cell, ours as shipped at or below every stock peer from 40 ms up.  The whole table is
``benchmarks/peers.py`` (written to ``benchmarks/peers_table.md``).

    .venv/bin/python benchmarks/run.py --only peers [--quick]
"""
from __future__ import annotations

import importlib.util
import math
from pathlib import Path

from harness import Table, log

DRIVER = Path(__file__).resolve().parents[1] / 'peers.py'


def _driver():
    """``benchmarks/peers.py`` (its name is taken by the ``benchmarks/peers/`` package)."""
    spec = importlib.util.spec_from_file_location('peers_table_driver', DRIVER)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def bench_peers(cfg, table: Table, raw: dict) -> None:
    """Run the peers table and add its rows and targets."""
    drv = _driver()
    t = drv.run_table(quick=cfg.quick, log=lambda m: log(f'peers: {m}'))
    med, lats = t['med'], t['lats']
    raw['peers'] = {'results': t['results'], 'designs': t['designs'], 'skipped': t['skipped'],
                    'wall_s': t['wall']}
    k = 0
    for tn in t['trajs']:
        for c in t['controllers']:
            cells = [med.get((c, tn, 50.0, lat)) for lat in lats]
            if cells[0] is None:
                continue
            k += 1
            detail = ', '.join(
                f'{lat * 1e3:g} ms ' + ('-' if m is None else
                                        f'{m["rms"] * 1e3:.3g}' + (' div' if m['div'] else ''))
                for lat, m in zip(lats, cells))
            table.add(f'P.{k}', f'{tn}, 50 Hz, {c}: RMS after 10 s at 0 ms',
                      cells[0]['rms'] * 1e3 if math.isfinite(cells[0]['rms']) else math.nan,
                      'mm', detail + ' (mm; median of 3 seeds)')
    a = drv.ahead(t)
    for key, rid, figure, target in (
            ('bringup', 'P.A', 'ours after bring-up (exact) / best peer, worst cell',
             'peers_bringup_ahead'),
            ('identified', 'P.C', 'ours after bring-up (identified) / best peer, worst cell',
             'peers_bringup_ahead'),
            ('default', 'P.B', 'ours as shipped (monitor_tune on) / best stock peer from '
             '40 ms, worst cell', 'peers_default_ahead'),
            ('untuned', 'P.D', 'ours, shipped gain, monitor_tune off / best stock peer from '
             '40 ms, worst cell', None)):
        behind = a[key]['behind']
        table.add(rid, figure, a[key]['worst_ratio'], 'x',
                  ('behind in ' + '; '.join(behind[:4]) + (' ...' if len(behind) > 4 else ''))
                  if behind else 'ahead in every cell',
                  target=target)
    for name, why in t['skipped'].items():
        table.note('P.skip', f'peer module {name} skipped', why)
