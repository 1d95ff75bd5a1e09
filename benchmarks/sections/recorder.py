"""Benchmark section: Recorder throughput: messages/s the recorder keeps without loss.

Run through ``benchmarks/run.py --only recorder``; helpers come from ``harness``.
"""
from __future__ import annotations

import json
import shutil
import subprocess
import sys
import time
from pathlib import Path

from harness import (
    HELPERS,
    PY,
    ROOT,
    Procs,
    Table,
    log,
    ros_env,
)


def bench_recorder(cfg, table: Table, raw: dict, domain: int, tmp: Path) -> None:
    check = subprocess.run([PY, '-c', 'import nonfragile_tracker.nodes.recorder, '
                            'nonfragile_tracker.bag.writer, rosbags.rosbag2'],
                           capture_output=True, text=True, cwd=str(ROOT))
    if check.returncode != 0:
        msg = 'recorder/bag modules not importable: ' + check.stderr.strip().splitlines()[-1]
        print(f'NOTE: skipping the recorder benchmark ({msg})', file=sys.stderr)
        table.note('4.6', 'recorder max sustained rate', msg)
        raw['recorder'] = {'skipped': msg}
        return
    from rosbags.rosbag2 import Reader
    env = ros_env(domain)
    res: dict = {'levels': []}
    raw['recorder'] = res
    best = None
    limited = False
    for rate in cfg.rec_rates:
        n = int(rate * cfg.rec_seconds)
        bag = tmp / f'bag_{rate}'
        log(f'recorder: {n} odom messages at {rate}/s')
        with Procs() as g:
            rec = g.start([PY, '-m', 'nonfragile_tracker.nodes.recorder', '--ros-args', '-p',
                           f'output:={bag}', '-p', "topics:=['odom']"], env,
                          tmp / f'rec_{rate}.log')
            pub = subprocess.run([PY, str(HELPERS), 'publish', '--topic', 'odom', '--rate',
                                  str(rate), '--count', str(n)], env=env, capture_output=True,
                                 text=True, timeout=120, cwd=str(ROOT), stdin=subprocess.DEVNULL)
            time.sleep(0.5)
            codes = g.stop(grace=20.0)
        info = next((json.loads(ln) for ln in pub.stdout.splitlines() if ln.startswith('{')), {})
        got = None
        try:
            rd = Reader(bag)
            rd.open()
            got = sum(c.msgcount for c in rd.connections if c.topic.endswith('odom'))
            rd.close()
        except Exception as exc:        # noqa: BLE001 - reported, not fatal
            info['read_error'] = str(exc)
        lvl = {'rate': rate, 'published': n, 'recorded': got, 'publisher': info,
               'recorder_exit': codes.get(rec.pid)}
        res['levels'].append(lvl)
        log(f'  recorded {got} of {n}; publisher {info}')
        achieved = info.get('achieved_rate') or 0.0
        if got is None or got < n:
            break
        best = (rate, achieved)
        if achieved < 0.9 * rate:
            limited = True
            break
        shutil.rmtree(bag, ignore_errors=True)
    res['max_sustained'] = best
    res['publisher_limited'] = limited
    last = res['levels'][-1] if res['levels'] else {}
    detail = ('; '.join(f"{lv['rate']}/s: {lv['recorded']}/{lv['published']}"
                        for lv in res['levels']))
    if limited:
        detail += '; publisher could not go faster'
    elif last and last.get('recorded') is not None and last['recorded'] < last['published']:
        detail += f"; drops from {last['rate']}/s"
    table.add('4.6', f'recorder: max rate without drops (odom, {cfg.rec_seconds:g} s/level)', float(best[1]) if best else None, 'msg/s', detail)
