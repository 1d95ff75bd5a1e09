"""Benchmark section, realtime latency: odom -> cmd_vel through the tracker vs an echo node.

Run through ``benchmarks/run.py --only realtime``; helpers come from ``harness``.

Like for like (issue 12's ratio): at 100 Hz the tracker and the bare echo node run side
by side, at the same time, each with its own plant and reference in a namespace of its
own (``/trk``, ``/echo``), observed by one probe over the same window - load bursts on
the machine hit both alike; the same executor (EventsExecutor) and QoS.  Three such
runs (start order alternating); the ratio of the median p99 latencies is the target.
The callback cost itself is timed in process on synthetic odometry
(``ros_helpers.py callback``).
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


def _rt_once(rate: float, env: dict, tmp: Path, cfg, tag: str) -> dict:
    """One real-time measurement: plant + reference + tracker + probe."""
    pf = write_params(tmp / f'rt_{tag}.yaml', realtime_params(rate))
    with Procs() as g:
        tr = g.start(node_cmd('tracker', pf), env, tmp / f'rt_{tag}_tracker.log')
        g.start(node_cmd('reference', pf), env, tmp / f'rt_{tag}_reference.log')
        pl = g.start(node_cmd('plant', pf), env, tmp / f'rt_{tag}_plant.log')
        data = run_probe(env, tmp / f'rt_{tag}.json', pids=(tr.pid, pl.pid),
                         warmup=cfg.rt_warmup, duration=cfg.rt_window)
    return _with_cpu(latency_stats(data['data']['/'], 1.0 / rate), data, tr.pid, pl.pid)


def _with_cpu(st: dict, data: dict, node_pid: int, plant_pid: int) -> dict:
    st.update(node_cpu=data['cpu_fraction'].get(str(node_pid)),
              plant_cpu=data['cpu_fraction'].get(str(plant_pid)),
              probe_cpu=data['probe_cpu_fraction'], window_s=data['window_s'],
              machine_busy_cores=data.get('machine_busy_cores'),
              load1=(data.get('loadavg') or [math.nan])[0])
    return st


#: Namespaces of the side-by-side measurement.
SIDE_NS = {'tracker': '/trk', 'echo': '/echo'}
#: Its window in units of ``cfg.rt_window`` (a longer window: a p99 that one load burst of
#: a few periods does not decide).
SIDE_WINDOW = 2


def _side_by_side(env: dict, tmp: Path, cfg, i: int) -> dict:
    """Tracker and bare echo at 100 Hz at the same time, each with its plant and reference."""
    pf = write_params(tmp / f'rt_side_{i}.yaml', realtime_params(100))
    order = ['tracker', 'echo'] if i % 2 == 0 else ['echo', 'tracker']
    pids = {}
    with Procs() as g:
        for kind in order:
            ns = SIDE_NS[kind]
            remap = ('-r', f'__ns:={ns}')
            cmd = node_cmd('tracker', pf, *remap) if kind == 'tracker' else \
                [PY, str(HELPERS), 'echo', '--ns', ns]
            node = g.start(cmd, env, tmp / f'rt_side_{i}_{kind}.log')
            g.start(node_cmd('reference', pf, *remap), env, tmp / f'rt_side_{i}_{kind}_ref.log')
            plant = g.start(node_cmd('plant', pf, *remap), env,
                            tmp / f'rt_side_{i}_{kind}_plant.log')
            pids[kind] = (node.pid, plant.pid)
        data = run_probe(env, tmp / f'rt_side_{i}.json', namespaces=','.join(SIDE_NS.values()),
                         pids=[p for pair in pids.values() for p in pair],
                         warmup=cfg.rt_warmup, duration=SIDE_WINDOW * cfg.rt_window)
    return {kind: _with_cpu(latency_stats(data['data'][ns], 0.01), data, *pids[kind])
            for kind, ns in SIDE_NS.items()}


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
        'from the odom header stamps (plant timer), late = interval > 1.5 period.  Ratio '
        '(4.5, 4.5.1): tracker and bare echo node side by side at 100 Hz, each with its own '
        'plant and reference in its own namespace, one probe, the same (2 x longer) window; '
        '3 runs; '
        'ratio = median tracker p99 / median echo p99'),
        'runs': {}}
    raw['realtime'] = res
    env = ros_env(domain)
    schedule = [(rate, i) for rate in cfg.rt_rates
                for i in range(cfg.rt_reps if rate == 100 else 1)]
    for rate, i in schedule:
        log(f'real time {rate} Hz, tracker rep {i}: plant + reference + tracker + probe '
            f'({cfg.rt_window} s window)')
        st = _rt_once(rate, env, tmp, cfg, f'tracker_{rate}_{i}')
        res['runs'].setdefault(f'tracker_{rate}', []).append(st)
        log('  ' + ', '.join(f'{k} {fmt(v) if isinstance(v, float) else v}'
                             for k, v in st.items()))
    for i in range(cfg.rt_reps):
        log(f'real time 100 Hz side by side, rep {i}: {SIDE_NS["tracker"]} plant + reference + '
            f'tracker and {SIDE_NS["echo"]} plant + reference + bare echo, one probe '
            f'({SIDE_WINDOW * cfg.rt_window} s window)')
        both = _side_by_side(env, tmp, cfg, i)
        for kind, st in both.items():
            res['runs'].setdefault(f'side_{kind}_100', []).append(st)
            log(f'  {kind}: ' + ', '.join(f'{k} {fmt(v) if isinstance(v, float) else v}'
                                          for k, v in st.items()))

    def agg(key: str, field: str) -> dict:
        return summary([r.get(field, math.nan) for r in res['runs'].get(key, [])])
    echo = {f: agg('side_echo_100', f) for f in ('lat_p50_ms', 'lat_p99_ms', 'lat_max_ms',
                                            'node_cpu')}
    res['echo_summary'] = echo
    for rate in cfg.rt_rates:
        key = f'tracker_{rate}'
        runs = res['runs'][key]
        p99, p50, mx = agg(key, 'lat_p99_ms'), agg(key, 'lat_p50_ms'), agg(key, 'lat_max_ms')
        cpu, rr = agg(key, 'node_cpu'), agg(key, 'rr_p99_ms')
        res[f'summary_{rate}'] = {'p99': p99, 'p50': p50, 'max': mx, 'cpu': cpu}
        ratio = 'side by side: 4.5.1' if rate == 100 else ''
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
        table.add('4.5', 'baseline: bare echo node p99, 100 Hz, side by side',
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
        pub = cost['tracker_to_publish']
        table.add('4.5.2', 'tracker odom callback, in process (synthetic)', tr['p50_us'], 'us',
                  f"p99 {fmt(tr['p99_us'])}; to cmd_vel p50 {fmt(pub['p50_us'])}; {tr['n']} "
                  f"calls; bare echo callback p50 {fmt(ec['p50_us'])}, p99 {fmt(ec['p99_us'])}",
                  f"x{fmt(tr['p50_us'] / ec['p50_us'])} echo callback")


def _ratio_row(table: Table, res: dict) -> None:
    """Issue 12: tracker p99 / bare echo p99 at 100 Hz, both measured in this run."""
    tr, ec = res['runs'].get('side_tracker_100', []), res['runs'].get('side_echo_100', [])

    def med(runs: list, field: str) -> float:
        return summary([r.get(field, math.nan) for r in runs])['median']
    ratio = med(tr, 'lat_p99_ms') / med(ec, 'lat_p99_ms')
    per_rep = [a.get('lat_p99_ms', math.nan) / b.get('lat_p99_ms', math.nan)
               for a, b in zip(tr, ec)]
    p50 = med(tr, 'lat_p50_ms') / med(ec, 'lat_p50_ms')
    loads = [r.get('load1', math.nan) for r in tr + ec]
    res['ratio_p99_100'] = {'ratio': ratio, 'per_rep': per_rep, 'ratio_p50': p50,
                            'load1': loads}
    table.add('4.5.1', 'tracker / bare echo latency p99, 100 Hz, same run', ratio, 'x echo',
              f"median {fmt(med(tr, 'lat_p99_ms'))} / {fmt(med(ec, 'lat_p99_ms'))} ms "
              f"(side by side, n={len(tr)}); per rep "
              f"{', '.join(fmt(r) for r in per_rep)}; p50 ratio {fmt(p50)}; load1 "
              f"{fmt(min(loads))}-{fmt(max(loads))}",
              target='latency_p99_ratio_100hz')
