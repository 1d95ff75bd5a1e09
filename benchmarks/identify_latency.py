#!/usr/bin/env python3
"""Latency identification on our own plant: configured vs identified (issue 11).

    .venv/bin/python benchmarks/identify_latency.py [--quick] [--ros] [--realtime]

For command latencies of 100, 200 and 300 ms, a 50 ms first-order lag on v and w,
odometry at 50 Hz with 1 mm / 1 mrad noise, the figure eight (radius 1 m, 0.2 rad/s)
with the shipped gain and no predictor, it records runs and identifies them:

* ``sim``       the in-process loop (control.simulation.plant and .tracker step functions, as a lockstep run);
* ``lockstep``  (``--ros``) the nodes composed in one process, lockstep, recorded bag;
* ``realtime``  (``--realtime``) the nodes composed, real time (20 s), recorded bag.

Each row: median over the seeds (3, ``--quick`` 1) of the identified latency and lags,
the largest latency error in plant steps (dt = 0.01 s), and MET/MISSED for the issue's
target (latency within one plant step, lags within 20 %).  In real time the plant applies
a command at its next timer tick, so the effective latency (``eff. L``) is the configured
one plus the mean wait from receipt to that tick, measured from the bag (ticks = ``pose``
stamps); ``tick sd`` is the standard deviation of the tick interval (timer jitter: the
plant integrates a nominal ``dt`` per tick, so jitter smears the response and inflates
the apparent lag).  ROS runs must be started in
a network namespace of their own (``ip netns exec <ns> ...`` with the loopback up, on a
shared machine) or on a quiet host.  Not part of the test suite.
"""
from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
CONFIG = ROOT / 'config'
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from nonfragile_tracker.control.identification.identify import (CommandSamples, OdometrySamples,  # noqa: E402
                                                 identify_latency)

DT = 0.01
LAG = 0.05
LATENCIES = (0.1, 0.2, 0.3)


def plant_parameters(latency: float, seed: int, duration: float, mode: str) -> dict:
    return {'plant': {'ros__parameters': dict(
                mode=mode, cmd_latency=latency, lag_v=LAG, lag_w=LAG, odom_rate=50.0,
                odom_noise=[0.001, 0.001, 0.001], noise_seed=seed, duration=duration)},
            'reference': {'ros__parameters': dict(mode=mode, path='figure_eight', radius=1.0,
                                                  rate=0.2)},
            'tracker': {'ros__parameters': dict(mode=mode, dt=0.02)}}


def record_sim(latency: float, seed: int, duration: float = 20.0):
    """Commands and odometry of the in-process loop, as the plant publishes them."""
    from nonfragile_tracker.control.simulation.gains import read_gain_file
    from nonfragile_tracker.control.simulation.plant import PlantConfig, UnicyclePlant
    from nonfragile_tracker.control.simulation.tracker import Tracker, TrackerConfig
    from nonfragile_tracker.control.simulation.model import quaternion_to_yaw, yaw_to_quaternion
    from nonfragile_tracker.control.simulation.timing import step_time
    from nonfragile_tracker.control.simulation.reference import make_path
    plant = UnicyclePlant(PlantConfig(dt=DT, cmd_latency=latency, lag_v=LAG, lag_w=LAG,
                                      odom_rate=50.0, odom_noise=(1e-3, 1e-3, 1e-3),
                                      noise_seed=seed))
    tracker = Tracker(TrackerConfig(K=read_gain_file(CONFIG / 'tracker_gains.yaml'), dt=0.02))
    path = make_path('figure_eight', radius=1.0, rate=0.2)
    cmds, odom = [], []
    for k in range(int(round(duration / DT)) + 1):
        meas = plant.odometry()
        if meas is not None:
            ts = step_time(meas.step, DT)
            th = quaternion_to_yaw(*yaw_to_quaternion(meas.th))
            cmd = tracker.step(meas.x, meas.y, th, path.sample(ts), meas.v, stamp=ts)
            plant.command(cmd.v, cmd.w)
            cmds.append((step_time(k, DT), cmd.v, cmd.w))
            odom.append((ts, meas.x, meas.y, th, meas.v, meas.w))
        plant.advance()
    c, o = np.array(cmds).T, np.array(odom).T
    return CommandSamples(*c), OdometrySamples(*o)


def record_lockstep(latency: float, seed: int, tmp: Path):
    from nonfragile_tracker.bag.motion import read_motion
    from nonfragile_tracker.workflows.runner import run_composed, scenario_parameters
    params = scenario_parameters(CONFIG / 'paper_scenario.yaml', CONFIG / 'tracker_gains.yaml',
                                 plant_parameters(latency, seed, 20.0, 'lockstep'))
    res = run_composed(params, tmp)
    if any(res.exit_codes.values()):
        raise RuntimeError(f'lockstep run failed: {res.exit_codes}')
    data = read_motion(res.bag)
    return data.commands, data.odometry


def record_realtime(latency: float, seed: int, tmp: Path, duration: float = 20.0):
    import rclpy
    from rclpy.parameter import Parameter

    from nonfragile_tracker.bag.motion import read_motion
    from nonfragile_tracker.nodes.common import make_executor
    from nonfragile_tracker.nodes.plant import PlantNode
    from nonfragile_tracker.nodes.recorder import Recorder
    from nonfragile_tracker.nodes.reference import ReferenceNode
    from nonfragile_tracker.nodes.tracker import TrackerNode
    from nonfragile_tracker.workflows.runner import reserved_domain, scenario_parameters
    params = scenario_parameters(CONFIG / 'paper_scenario.yaml', CONFIG / 'tracker_gains.yaml',
                                 plant_parameters(latency, seed, duration, 'realtime'))

    def over(name):
        return [Parameter(k, value=v) for k, v in params[name]['ros__parameters'].items()]

    domain = reserved_domain()
    env = domain.__enter__()          # the domain is ours until the run's end (finally below)
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=int(env['ROS_DOMAIN_ID']))
    nodes = []
    try:
        nodes.append(Recorder(context=ctx, parameter_overrides=[
            Parameter('output', value=str(tmp / 'bag'))]))
        nodes.append(TrackerNode(parameter_overrides=over('tracker'), context=ctx))
        nodes.append(ReferenceNode(parameter_overrides=over('reference'), context=ctx))
        plant = PlantNode(parameter_overrides=over('plant'), context=ctx)
        nodes.append(plant)
        ex = make_executor(ctx)
        for n in nodes:
            ex.add_node(n)
        t0 = time.monotonic()
        while ctx.ok() and time.monotonic() - t0 < duration + 30 and not plant.finished:
            ex.spin_once(timeout_sec=0.05)
    finally:
        for n in nodes:
            close = getattr(n, 'close', None)
            if close is not None:
                close()
            n.destroy_node()
        rclpy.try_shutdown(context=ctx)
        domain.__exit__(None, None, None)
    data = read_motion(tmp / 'bag')
    # the plant applies a command at its next timer tick: the effective latency is the
    # configured one plus the wait from receipt to that tick (ticks = pose stamps)
    from nonfragile_tracker.bag.reader import read_messages
    ticks = np.array([m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec
                      for _, m in read_messages(tmp / 'bag', 'pose')])
    j = np.searchsorted(ticks, data.commands.t, side='right')
    ok = j < ticks.size
    wait = float(np.mean(ticks[j[ok]] - data.commands.t[ok]))
    jitter = float(np.std(np.diff(ticks)))
    return data.commands, data.odometry, wait, jitter


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument('--quick', action='store_true', help='one seed per latency')
    ap.add_argument('--ros', action='store_true', help='also lockstep runs of the nodes')
    ap.add_argument('--realtime', action='store_true', help='also real-time runs (20 s each)')
    args = ap.parse_args()
    seeds = (1,) if args.quick else (1, 2, 3)
    modes = ['sim'] + (['lockstep'] if args.ros else []) + (['realtime'] if args.realtime
                                                             else [])
    rows = []
    for mode in modes:
        for lat in LATENCIES:
            est, waits, jitters = [], [], []
            for seed in seeds:
                print(f'{mode} latency {lat:.3f} s seed {seed} ...', file=sys.stderr)
                with tempfile.TemporaryDirectory() as d:
                    if mode == 'sim':
                        cmd, odom = record_sim(lat, seed)
                    elif mode == 'lockstep':
                        cmd, odom = record_lockstep(lat, seed, Path(d))
                    else:
                        cmd, odom, wait, jitter = record_realtime(lat, seed, Path(d))
                        waits.append(wait)
                        jitters.append(jitter)
                t0 = time.perf_counter()
                res = identify_latency(cmd, odom)
                est.append((res, time.perf_counter() - t0))
            lats = [r.latency_s for r, _ in est]
            eff = [lat + w for w in waits] if waits else [lat] * len(lats)
            err = max(abs(x - e) for x, e in zip(lats, eff)) / DT
            tv = [r.tau_v_s for r, _ in est]
            tw = [r.tau_w_s for r, _ in est]
            ok = err <= 1.0 and all(abs(t - LAG) <= 0.2 * LAG for t in tv + tw)
            rows.append((mode, lat, statistics.median(eff),
                         statistics.median(jitters) if jitters else 0.0,
                         statistics.median(lats),
                         statistics.median(r.latency_low_s for r, _ in est),
                         statistics.median(r.latency_high_s for r, _ in est), err,
                         statistics.median(tv), statistics.median(tw),
                         statistics.median(t for _, t in est), len(est),
                         'MET' if ok else 'MISSED'))
    print(f'{"mode":<9} {"config L":>8} {"eff. L":>7} {"tick sd":>7} {"ident. L":>9} '
          f'{"interval":>17} {"max err":>8} {"tau_v":>7} {"tau_w":>7} {"fit s":>6} {"n":>2}  '
          'target (L +-1 step of eff. L, tau +-20 %)')
    for mode, lat, eff, jit, med, lo, hi, err, tv, tw, secs, n, ok in rows:
        print(f'{mode:<9} {lat:8.3f} {eff:7.4f} {jit:7.4f} {med:9.4f} [{lo:.4f}, {hi:.4f}] '
              f'{err:5.2f} st {tv:7.4f} {tw:7.4f} {secs:6.2f} {n:2d}  {ok}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
