"""Benchmark section, realtime latency: odom -> cmd_vel through the tracker vs an echo node.

Run through ``benchmarks/run.py --only realtime``; helpers come from ``harness``.

Like for like: at 100 Hz the tracker and the bare echo node are measured in
interleaved repetitions (tracker, echo / echo, tracker / ...) with the same
processes around them - plant, reference (unused by the echo) and probe - the
same executor (EventsExecutor) and QoS; the ratio of their p99 latencies (median
of the repetitions) is the issue-12 target.  The callback cost itself is timed in
process on synthetic odometry (``ros_helpers.py callback``).
"""
from __future__ import annotations

import math
from pathlib import Path

import json
import subprocess

from harness import (
    HELPERS,
    PY,
    ROOT,
    Procs,
    Table,
    fmt,
    log,
    node_cmd,
    realtime_params,
    ros_env,
    run_probe,
    spread,
    summary,
    write_params,
)


def latency_stats(rec: dict, period: float) -> dict:
    """Tracker latency and plant deadlines from one namespace of a probe record."""
    import numpy as np
    o_src = np.asarray(rec['odom']['src'], dtype=np.int64)
    o_rcv = np.asarray(rec['odom']['rcv'], dtype=np.int64)
    o_st = np.asarray(rec['odom']['stamp'], dtype=np.int64)
    c_src = np.asarray(rec['cmd']['src'], dtype=np.int64)
    c_rcv = np.asarray(rec['cmd']['rcv'], dtype=np.int64)
    out: dict = {'odom': int(o_src.size), 'cmd': int(c_src.size)}
    if o_st.size > 1:
        iv = np.diff(np.sort(o_st)) * 1e-9
        late = iv > 1.5 * period
        out.update(interval_p50_ms=float(np.median(iv) * 1e3),
                   interval_max_ms=float(iv.max() * 1e3), late=int(late.sum()),
                   late_fraction=float(late.mean()), intervals=int(iv.size))
    if o_src.size and c_src.size:
        # each cmd_vel is paired with the last odom written before it (one command per pose):
        # latency = cmd write time - odom write time (DDS source timestamps, same host clock)
        i = np.searchsorted(o_src, c_src, side='right') - 1
        ok = i >= 0
        first = np.zeros(o_src.size, bool)
        pair = []
        for ci, oi in zip(np.flatnonzero(ok), i[ok]):
            if not first[oi]:
                first[oi] = True
                pair.append((ci, oi))
        if pair:
            ci, oi = map(np.asarray, zip(*pair))
            lat = (c_src[ci] - o_src[oi]) * 1e-6
            lat_rr = (c_rcv[ci] - o_rcv[oi]) * 1e-6
            out.update(pairs=len(pair), lat_p50_ms=float(np.percentile(lat, 50)),
                       lat_p99_ms=float(np.percentile(lat, 99)), lat_max_ms=float(lat.max()),
                       rr_p50_ms=float(np.percentile(lat_rr, 50)),
                       rr_p99_ms=float(np.percentile(lat_rr, 99)),
                       rr_max_ms=float(lat_rr.max()),
                       hop_p50_ms=float(np.median((o_rcv - o_src) * 1e-6)))
    return out


def _rt_once(kind: str, rate: float, env: dict, tmp: Path, cfg, tag: str) -> dict:
    """One real-time measurement: plant + reference + tracker (or bare echo) + probe.

    The reference runs in the echo measurement too (the echo ignores it), so both see
    the same processes and the same DDS traffic on the machine.
    """
    pf = write_params(tmp / f'rt_{tag}.yaml', realtime_params(rate))
    with Procs() as g:
        if kind == 'tracker':
            tr = g.start(node_cmd('tracker', pf), env, tmp / f'rt_{tag}_tracker.log')
        else:
            tr = g.start([PY, str(HELPERS), 'echo'], env, tmp / f'rt_{tag}_echo.log')
        g.start(node_cmd('reference', pf), env, tmp / f'rt_{tag}_reference.log')
        pl = g.start(node_cmd('plant', pf), env, tmp / f'rt_{tag}_plant.log')
        data = run_probe(env, tmp / f'rt_{tag}.json', pids=(tr.pid, pl.pid),
                         warmup=cfg.rt_warmup, duration=cfg.rt_window)
    st = latency_stats(data['data']['/'], 1.0 / rate)
    st.update(node_cpu=data['cpu_fraction'].get(str(tr.pid)),
              plant_cpu=data['cpu_fraction'].get(str(pl.pid)),
              probe_cpu=data['probe_cpu_fraction'], window_s=data['window_s'],
              machine_busy_cores=data.get('machine_busy_cores'),
              load1=(data.get('loadavg') or [math.nan])[0])
    return st


def _callback_cost(env: dict, tmp: Path) -> dict | None:
    """In-process callback times of the tracker and the echo (``ros_helpers.py callback``)."""
    pf = write_params(tmp / 'rt_callback.yaml', realtime_params(100))
    try:
        out = subprocess.run([PY, str(HELPERS), 'callback', '--params', str(pf)], env=env,
                             capture_output=True, text=True, timeout=120, check=True,
                             stdin=subprocess.DEVNULL, cwd=str(ROOT)).stdout
        return json.loads(out.strip().splitlines()[-1])
    except (subprocess.SubprocessError, ValueError, IndexError) as exc:
        log(f'  callback timing failed: {exc}')
        return None


def bench_realtime(cfg, table: Table, raw: dict, domain: int, tmp: Path) -> None:
    res: dict = {'method': (
        'probe process subscribes odom and cmd_vel (raw, SingleThreadedExecutor) and records '
        'the DDS source (write) and received timestamps of every message; each cmd_vel is '
        'paired with the last odom written before it; latency = cmd_vel write time - odom '
        'write time (plant -> tracker hop + tracker callback up to its publish); deadlines '
        'from the odom header stamps (plant timer), late = interval > 1.5 period; at 100 Hz '
        'tracker and bare echo node alternate (ABBA order) with the same processes around '
        'them (plant, reference, probe); ratio = median tracker p99 / median echo p99'),
        'runs': {}}
    raw['realtime'] = res
    env = ros_env(domain)
    schedule = []
    for rate in cfg.rt_rates:
        reps = cfg.rt_reps if rate == 100 else 1
        for i in range(reps):
            pair = [('tracker', rate, i), ('echo', rate, i)] if rate == 100 else \
                [('tracker', rate, i)]
            schedule.extend(pair if i % 2 == 0 else pair[::-1])   # interleaved, ABBA
    for kind, rate, i in schedule:
        log(f'real time {rate} Hz, {kind} rep {i}: plant + '
            f"reference + {'tracker' if kind == 'tracker' else 'bare echo node'} + probe "
            f'({cfg.rt_window} s window)')
        st = _rt_once(kind, rate, env, tmp, cfg, f'{kind}_{rate}_{i}')
        res['runs'].setdefault(f'{kind}_{rate}', []).append(st)
        log('  ' + ', '.join(f'{k} {fmt(v) if isinstance(v, float) else v}'
                             for k, v in st.items()))

    def agg(key: str, field: str) -> dict:
        return summary([r.get(field, math.nan) for r in res['runs'].get(key, [])])
    echo = {f: agg('echo_100', f) for f in ('lat_p50_ms', 'lat_p99_ms', 'lat_max_ms',
                                            'node_cpu')}
    res['echo_summary'] = echo
    for rate in cfg.rt_rates:
        key = f'tracker_{rate}'
        runs = res['runs'][key]
        p99, p50, mx = agg(key, 'lat_p99_ms'), agg(key, 'lat_p50_ms'), agg(key, 'lat_max_ms')
        cpu, rr = agg(key, 'node_cpu'), agg(key, 'rr_p99_ms')
        res[f'summary_{rate}'] = {'p99': p99, 'p50': p50, 'max': mx, 'cpu': cpu}
        ratio = ''
        if rate == 100 and echo['lat_p99_ms']['n']:
            ratio = (f"x{fmt(p99['median'] / echo['lat_p99_ms']['median'])} bare echo "
                     f"(p99 {fmt(echo['lat_p99_ms']['median'])} ms)")
        table.add(f'4.3.{rate}', f'tracker latency p99, real time {rate} Hz', p99['median'],
                  'ms', (spread(p99) + '; ' if p99['n'] > 1 else '') +
                  f"p50 {fmt(p50['median'])}, max {fmt(mx['max'])}; probe rcv->rcv p99 "
                  f"{fmt(rr['median'])}; {sum(r.get('pairs', 0) for r in runs)} pairs",
                  ratio, target='latency_p99_100hz' if rate == 100 else None)
        late = sum(r.get('late', 0) for r in runs)
        ivs = sum(r.get('intervals', 0) for r in runs)
        table.add(f'4.4.{rate}', f'  tracker CPU, missed plant deadlines, {rate} Hz',
                  100 * cpu['median'], '% of a core',
                  f"{late}/{ivs} steps late (>1.5 period), max interval "
                  f"{fmt(max(r.get('interval_max_ms', math.nan) for r in runs))} ms; plant CPU "
                  f"{fmt(100 * agg(key, 'plant_cpu')['median'])}%; machine busy "
                  f"{fmt(agg(key, 'machine_busy_cores')['median'])} of 2 cores")
    if echo['lat_p99_ms']['n']:
        table.add('4.5', 'baseline: bare echo node latency p99, 100 Hz',
                  echo['lat_p99_ms']['median'], 'ms',
                  (spread(echo['lat_p99_ms']) + '; ' if echo['lat_p99_ms']['n'] > 1 else '') +
                  f"p50 {fmt(echo['lat_p50_ms']['median'])}, max "
                  f"{fmt(echo['lat_max_ms']['max'])}; echo CPU "
                  f"{fmt(100 * echo['node_cpu']['median'])}%")
        _ratio_row(table, res)
    cost = _callback_cost(env, tmp)
    res['callback_us'] = cost
    if cost:
        tr, ec = cost['tracker'], cost['echo']
        table.add('4.7', 'tracker odom callback, in process (synthetic odom)', tr['p50_us'], 'us',
                  f"p99 {fmt(tr['p99_us'])}; {tr['n']} calls; bare echo callback p50 "
                  f"{fmt(ec['p50_us'])}, p99 {fmt(ec['p99_us'])}",
                  f"x{fmt(tr['p50_us'] / ec['p50_us'])} echo callback")


def _ratio_row(table: Table, res: dict) -> None:
    """Issue 12: tracker p99 / bare echo p99 at 100 Hz, both measured in this run."""
    tr, ec = res['runs'].get('tracker_100', []), res['runs'].get('echo_100', [])

    def med(runs: list, field: str) -> float:
        return summary([r.get(field, math.nan) for r in runs])['median']
    ratio = med(tr, 'lat_p99_ms') / med(ec, 'lat_p99_ms')
    per_rep = [a.get('lat_p99_ms', math.nan) / b.get('lat_p99_ms', math.nan)
               for a, b in zip(tr, ec)]
    p50 = med(tr, 'lat_p50_ms') / med(ec, 'lat_p50_ms')
    loads = [r.get('load1', math.nan) for r in tr + ec]
    res['ratio_p99_100'] = {'ratio': ratio, 'per_rep': per_rep, 'ratio_p50': p50,
                            'load1': loads}
    table.add('4.6', 'tracker / bare echo latency p99, 100 Hz, same run', ratio, 'x echo',
              f"median {fmt(med(tr, 'lat_p99_ms'))} / {fmt(med(ec, 'lat_p99_ms'))} ms "
              f"(n={len(tr)}/{len(ec)}, interleaved); per rep "
              f"{', '.join(fmt(r) for r in per_rep)}; p50 ratio {fmt(p50)}; load1 "
              f"{fmt(min(loads))}-{fmt(max(loads))}",
              target='latency_p99_ratio_100hz')
