"""Benchmark: `bag report` on a 10-minute real-time bag at 100 Hz (issue 13: target < 10 s).

Standalone (not a test): synthesizes the bag with rosbags - odometry at 100 Hz with
stamp jitter, the three reference topics at 100 Hz on another phase, commands
(Twist) 2-4 ms after each odometry, 300,000 messages - then times
``bag_report`` with the four PNG plots and without, and the in-process replay of
the same bag, and prints one table: median of ``--repeat`` runs, min-max, target.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bag_report.py [--minutes 10] [--repeat 3]

The machine is shared: the load average is printed with the figures.
"""
from __future__ import annotations

import argparse
import math
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from rosbags.rosbag2 import Writer  # noqa: E402
from rosbags.typesys import Stores, get_typestore  # noqa: E402

from nonfragile_tracker.bag.replay import replay  # noqa: E402
from nonfragile_tracker.bag.report import bag_report  # noqa: E402


def synthesize(path: Path, minutes: float, rate: float = 100.0) -> int:
    ts = get_typestore(Stores.ROS2_JAZZY)
    T = ts.types
    n = int(minutes * 60 * rate)
    rng = np.random.default_rng(1)
    t0 = 1_700_000_000 * 10 ** 9
    step = int(round(1e9 / rate))
    stamps = t0 + np.arange(n) * step + rng.integers(-300_000, 300_000, n)
    cov = np.zeros(36)
    R, W = 0.5, 0.01

    def header(ns, frame='odom'):
        return T['std_msgs/msg/Header'](stamp=T['builtin_interfaces/msg/Time'](
            sec=int(ns // 10 ** 9), nanosec=int(ns % 10 ** 9)), frame_id=frame)

    def vec(x=0.0, y=0.0, z=0.0):
        return T['geometry_msgs/msg/Vector3'](x=x, y=y, z=z)

    def pose(x, y, yaw):
        return T['geometry_msgs/msg/Pose'](
            position=T['geometry_msgs/msg/Point'](x=x, y=y, z=0.0),
            orientation=T['geometry_msgs/msg/Quaternion'](x=0.0, y=0.0, z=math.sin(yaw / 2),
                                                          w=math.cos(yaw / 2)))
    count = 0
    with Writer(path, version=9) as w:
        c = {name: w.add_connection(topic, typ, typestore=ts) for name, topic, typ in (
            ('odom', '/odom', 'nav_msgs/msg/Odometry'),
            ('pose', '/reference/pose', 'geometry_msgs/msg/PoseStamped'),
            ('twist', '/reference/twist', 'geometry_msgs/msg/TwistStamped'),
            ('accel', '/reference/accel', 'geometry_msgs/msg/AccelStamped'),
            ('cmd', '/cmd_vel', 'geometry_msgs/msg/Twist'))}
        for k in range(n):
            t = k / rate
            a = W * t
            ref_ns = t0 + k * step + step // 2
            hdr = header(ref_ns)
            recs = [
                (int(stamps[k]) + 1_000_000, 'odom', T['nav_msgs/msg/Odometry'](
                    header=header(stamps[k]), child_frame_id='base_link',
                    pose=T['geometry_msgs/msg/PoseWithCovariance'](
                        pose=pose(0.51 * math.cos(a), 0.51 * math.sin(a), a + math.pi / 2),
                        covariance=cov),
                    twist=T['geometry_msgs/msg/TwistWithCovariance'](
                        twist=T['geometry_msgs/msg/Twist'](linear=vec(R * W),
                                                           angular=vec(z=W)),
                        covariance=cov))),
                (ref_ns + 500_000, 'pose', T['geometry_msgs/msg/PoseStamped'](
                    header=hdr, pose=pose(R * math.cos(a), R * math.sin(a), a + math.pi / 2))),
                (ref_ns + 500_001, 'twist', T['geometry_msgs/msg/TwistStamped'](
                    header=hdr, twist=T['geometry_msgs/msg/Twist'](
                        linear=vec(-R * W * math.sin(a), R * W * math.cos(a)), angular=vec()))),
                (ref_ns + 500_002, 'accel', T['geometry_msgs/msg/AccelStamped'](
                    header=hdr, accel=T['geometry_msgs/msg/Accel'](
                        linear=vec(-R * W * W * math.cos(a), -R * W * W * math.sin(a)),
                        angular=vec()))),
                (int(stamps[k]) + 3_000_000 + int(rng.integers(-1_000_000, 1_000_000)), 'cmd',
                 T['geometry_msgs/msg/Twist'](linear=vec(R * W), angular=vec(z=W))),
            ]
            for recv, name, msg in sorted(recs, key=lambda r: r[0]):
                w.write(c[name], recv, ts.serialize_cdr(msg, c[name].msgtype))
                count += 1
    return count


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--minutes', type=float, default=10.0)
    ap.add_argument('--repeat', type=int, default=3)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix='nf_bench_bag_') as tmp:
        bag = Path(tmp) / 'bag'
        t = time.perf_counter()
        msgs = synthesize(bag, args.minutes)
        synth = time.perf_counter() - t
        size = sum(p.stat().st_size for p in bag.iterdir()) / 1e6
        print(f'synthesized {msgs} messages ({size:.1f} MB) in {synth:.1f} s', file=sys.stderr)
        rows = []
        for label, fn, target in (
                ('bag report (text + 4 PNG plots)',
                 lambda i: bag_report(bag, Path(tmp) / f'r{i}'), 10.0),
                ('bag report --no-plots', lambda i: bag_report(bag, plots=False), 10.0),
                ('bag replay (in process)', lambda i: replay(bag), None)):
            times = []
            for i in range(args.repeat):
                t = time.perf_counter()
                fn(i)
                times.append(time.perf_counter() - t)
            rows.append((label, statistics.median(times), min(times), max(times), target))
    load = os.getloadavg()
    print(f'# bag_report benchmark: {args.minutes:g} min real-time bag at 100 Hz, {msgs} '
          f'messages, {size:.1f} MB; load average {load[0]:.2f} {load[1]:.2f} (shared machine)')
    print(f'{"case":<34} {"median s":>9} {"min-max s":>13} {"n":>2}  target')
    for label, med, lo, hi, target in rows:
        verdict = '' if target is None else (f'< {target:g} s ' +
                                             ('MET' if med < target else 'MISSED'))
        print(f'{label:<34} {med:9.2f} {lo:6.2f}-{hi:<6.2f} {args.repeat:>2}  {verdict}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
