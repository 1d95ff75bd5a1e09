"""ROS-side helper processes of the benchmark (started by ``benchmarks/run.py``).

Nothing here is part of the package; each subcommand is one short-lived process:

* ``probe``    - subscribes ``odom`` and (optionally) ``cmd_vel`` of one or more
  namespaces with raw (CDR) subscriptions and records, per message, the header
  stamp (odom) and the DDS ``source_timestamp`` (publisher's write time) and
  ``received_timestamp`` (arrival in this process) from the rmw message info.
  It also samples ``/proc/<pid>/stat`` (utime + stime) of the given pids and the
  machine's busy time (``/proc/stat``) at the start and the end of the window.  Writes one JSON file.
* ``publish``  - publishes ``count`` nav_msgs/Odometry messages on a topic at a
  fixed rate (for the recorder's sustained-rate test), after the subscriber is
  matched; prints the achieved rate as JSON.
* ``echo``     - the bare baseline of the tracker's latency: subscribes ``odom``
  and publishes a ``cmd_vel`` Twist from each, on the EventsExecutor (as the nodes,
  ``nodes.common.make_executor``) with the nodes' QoS; ``--ns`` puts it in a namespace.
* ``callback`` - in process, no other node: times the tracker's odometry callback
  (real-time parameters from ``--params``; a fresh reference sample before each
  odometry, as at equal rates) and the echo's, on the same synthetic messages, by
  calling the subscriptions' callbacks as the executor does; prints JSON (us).
* ``composed`` - runs ``runner.run_composed`` (lockstep, three nodes in this
  process, no recording) for a duration; prints its wall time as JSON.  The
  orchestrator also parses the plant's log lines (stderr) for the in-run rate.
"""
from __future__ import annotations

import argparse
import json
import os
import struct
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:          # this checkout's package, not an installed one
    sys.path.insert(0, str(ROOT))


def _cpu_ticks(pid: int) -> int | None:
    """utime + stime of a process in clock ticks (None if it is gone)."""
    try:
        text = Path(f'/proc/{pid}/stat').read_text()
    except OSError:
        return None
    fields = text.rsplit(')', 1)[1].split()
    return int(fields[11]) + int(fields[12])      # fields 14 and 15 of proc(5)


def _cpu_busy() -> tuple[int, int]:
    """(busy, total) jiffies of all CPUs from /proc/stat."""
    vals = [int(v) for v in Path('/proc/stat').read_text().splitlines()[0].split()[1:]]
    idle = vals[3] + (vals[4] if len(vals) > 4 else 0)
    return sum(vals) - idle, sum(vals)


def _stamp(raw: bytes) -> int:
    """Header stamp (ns) of a CDR message whose first field is a std_msgs/Header."""
    fmt = '<iI' if raw[1] & 1 else '>iI'
    sec, nsec = struct.unpack_from(fmt, raw, 4)
    return sec * 1_000_000_000 + nsec


def cmd_probe(args) -> int:
    import rclpy
    from geometry_msgs.msg import Twist
    from nav_msgs.msg import Odometry
    from nonfragile_tracker.interface import topics
    from nonfragile_tracker.nodes.common import DATA_QOS as qos
    namespaces = [n for n in args.namespaces.split(',')] if args.namespaces else ['']
    pids = [int(p) for p in args.pids.split(',') if p] if args.pids else []
    rclpy.init()
    node = rclpy.create_node('bench_probe')
    state = {'recording': False}
    data: dict[str, dict[str, list]] = {}

    seen: set[str] = set()

    def odom_cb(rec, key):
        def cb(raw, info):
            if state['recording']:
                rec['stamp'].append(_stamp(raw))
                rec['src'].append(info['source_timestamp'])
                rec['rcv'].append(info['received_timestamp'])
            seen.add(key)
        return cb

    def cmd_cb(rec, key):
        def cb(raw, info):
            if state['recording']:
                rec['src'].append(info['source_timestamp'])
                rec['rcv'].append(info['received_timestamp'])
            seen.add(key)
        return cb

    for ns in namespaces:
        prefix = (ns.rstrip('/') + '/') if ns else ''
        odom = {'stamp': [], 'src': [], 'rcv': []}
        cmd = {'src': [], 'rcv': []}
        data[ns or '/'] = {'odom': odom, 'cmd': cmd}
        node.create_subscription(Odometry, prefix + topics.ODOM, odom_cb(odom, ns or '/'), qos,
                                 raw=True)
        if not args.no_cmd:
            node.create_subscription(Twist, prefix + topics.CMD_VEL,
                                     cmd_cb(cmd, 'cmd:' + (ns or '/')), qos, raw=True)
    if args.executor == 'events':
        from rclpy.experimental import EventsExecutor
        ex = EventsExecutor()
    else:
        ex = rclpy.executors.SingleThreadedExecutor()
    ex.add_node(node)
    t_start = time.monotonic()
    # wait for odom (and cmd_vel: the node under test is up) from every namespace (or give
    # up), then the warm-up, then the window
    expected = len(data) * (1 if args.no_cmd else 2)
    while len(seen) < expected and time.monotonic() - t_start < args.wait:
        ex.spin_once(timeout_sec=0.05)
    first = time.monotonic()
    while time.monotonic() - first < args.warmup:
        ex.spin_once(timeout_sec=0.05)
    ticks0 = {p: _cpu_ticks(p) for p in pids}
    self0 = _cpu_ticks(os.getpid())
    busy0 = _cpu_busy()
    state['recording'] = True
    w0 = time.monotonic()
    while time.monotonic() - w0 < args.duration:
        ex.spin_once(timeout_sec=0.05)
    state['recording'] = False
    window = time.monotonic() - w0
    ticks1 = {p: _cpu_ticks(p) for p in pids}
    self1 = _cpu_ticks(os.getpid())
    busy1 = _cpu_busy()
    hz = os.sysconf('SC_CLK_TCK')
    total = busy1[1] - busy0[1]
    machine_busy = (busy1[0] - busy0[0]) / total * (os.cpu_count() or 1) if total else None
    cpu = {str(p): (None if ticks0[p] is None or ticks1[p] is None
                    else (ticks1[p] - ticks0[p]) / hz / window) for p in pids}
    out = {'window_s': window, 'waited_s': first - t_start, 'saw': sorted(seen),
           'cpu_fraction': cpu, 'probe_cpu_fraction': (self1 - self0) / hz / window,
           'machine_busy_cores': machine_busy, 'loadavg': os.getloadavg(),
           'data': data}
    Path(args.out).write_text(json.dumps(out))
    ex.shutdown(timeout_sec=1.0)
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


def cmd_publish(args) -> int:
    import rclpy
    from nav_msgs.msg import Odometry
    from nonfragile_tracker.nodes.common import DATA_QOS as qos
    rclpy.init()
    node = rclpy.create_node('bench_publisher')
    pub = node.create_publisher(Odometry, args.topic, qos)
    t0 = time.monotonic()
    while pub.get_subscription_count() < 1:
        if time.monotonic() - t0 > args.wait:
            print(json.dumps({'error': 'no subscriber matched'}))
            return 3
        time.sleep(0.01)
    time.sleep(0.2)                       # let the match settle on both sides
    msg = Odometry()
    msg.header.frame_id = 'odom'
    msg.child_frame_id = 'base_link'
    period = 1.0 / args.rate
    start = time.perf_counter()
    late = 0
    for i in range(args.count):
        due = start + i * period
        now = time.perf_counter()
        if due > now:
            delay = due - now
            if delay > 2e-4:
                time.sleep(delay - 1e-4)
            while time.perf_counter() < due:
                pass
        elif now - due > period:
            late += 1
        ns = 1_000_000_000 + i * 1000
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(ns, 1_000_000_000)
        msg.pose.pose.position.x = float(i)
        pub.publish(msg)
    elapsed = time.perf_counter() - start
    from rclpy.duration import Duration
    acked = pub.wait_for_all_acked(Duration(seconds=5.0))
    print(json.dumps({'count': args.count, 'elapsed_s': elapsed,
                      'achieved_rate': args.count / elapsed if elapsed > 0 else None,
                      'late': late, 'all_acked': bool(acked)}))
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


def _echo_node(rclpy, namespace: str = ''):
    """The bare echo: odom in (deserialized), one preallocated Twist out, nothing else."""
    from geometry_msgs.msg import Twist
    from nav_msgs.msg import Odometry
    from nonfragile_tracker.interface import topics
    from nonfragile_tracker.nodes.common import DATA_QOS as qos
    node = rclpy.create_node('bench_echo', namespace=namespace)
    pub = node.create_publisher(Twist, topics.CMD_VEL, qos)
    out = Twist()

    def cb(msg):
        out.linear.x = msg.twist.twist.linear.x
        pub.publish(out)

    node.create_subscription(Odometry, topics.ODOM, cb, qos)
    return node


def cmd_echo(args) -> int:
    """Bare baseline of the tracker: odom in (deserialized), a Twist out, nothing else."""
    import rclpy
    from nonfragile_tracker.nodes.common import make_executor
    rclpy.init()
    node = _echo_node(rclpy, args.ns)
    ex = make_executor()
    ex.add_node(node)
    try:
        while rclpy.ok():
            ex.spin_once(timeout_sec=0.1)
    except KeyboardInterrupt:
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


def _subscription(node, topic: str):
    name = node.resolve_topic_name(topic)
    return next(s for s in node.subscriptions if s.topic_name == name)


def cmd_callback(args) -> int:
    """Per-call time of the tracker's and the echo's odometry callbacks (in process)."""
    import math as m
    import rclpy
    from geometry_msgs.msg import AccelStamped, PoseStamped, TwistStamped
    from nav_msgs.msg import Odometry
    from nonfragile_tracker.interface import topics
    from nonfragile_tracker.interface.msgconv import fill_pose, ns_to_stamp
    from nonfragile_tracker.nodes.tracker import TrackerNode
    rclpy.init(args=['--ros-args', '--params-file', args.params])
    tracker = TrackerNode()
    echo = _echo_node(rclpy)
    n, period, r, w = args.calls, 10_000_000, 0.5, 0.02    # paper circle: 0.5 m, 0.02 rad/s
    steps = []
    for i in range(n + args.warmup):
        t = 1.0 + i * period * 1e-9
        ph = w * t
        stamp = 1_000_000_000 + i * period
        msgs = [Odometry(), PoseStamped(), TwistStamped(), AccelStamped()]
        for msg in msgs:
            msg.header.frame_id = topics.ODOM_FRAME
            ns_to_stamp(stamp, msg.header.stamp)
        odom, pose, twist, accel = msgs
        odom.child_frame_id = topics.BASE_FRAME
        fill_pose(odom.pose.pose, r * m.cos(ph) + 1e-3, r * m.sin(ph), ph + m.pi / 2)
        odom.twist.twist.linear.x = r * w
        fill_pose(pose.pose, r * m.cos(ph), r * m.sin(ph), ph + m.pi / 2)
        twist.twist.linear.x, twist.twist.linear.y = -r * w * m.sin(ph), r * w * m.cos(ph)
        accel.accel.linear.x = -r * w * w * m.cos(ph)
        accel.accel.linear.y = -r * w * w * m.sin(ph)
        steps.append(msgs)
    subs = [_subscription(tracker, t).callback for t in
            (topics.ODOM, topics.REF_POSE, topics.REF_TWIST, topics.REF_ACCEL)]
    echo_cb = _subscription(echo, topics.ODOM).callback
    clock = time.perf_counter_ns
    sent = [0]

    class Stamped:
        """cmd_vel publisher of the tracker, noting when its publish returned."""

        def __init__(self, pub):
            self.pub = pub

        def publish(self, msg):
            self.pub.publish(msg)
            sent[0] = clock()

        def __getattr__(self, name):
            return getattr(self.pub, name)

    tracker.pub_cmd = Stamped(tracker.pub_cmd)
    times: dict[str, list[int]] = {'tracker': [], 'tracker_to_publish': [], 'echo': []}
    for i, (odom, pose, twist, accel) in enumerate(steps):
        subs[1](pose)
        subs[2](twist)
        subs[3](accel)
        t0 = clock()
        subs[0](odom)
        t1 = clock()
        echo_cb(odom)
        t2 = clock()
        if i >= args.warmup:
            times['tracker'].append(t1 - t0)
            times['tracker_to_publish'].append(sent[0] - t0)
            times['echo'].append(t2 - t1)
    out = {}
    for key, ts in times.items():
        ts.sort()
        out[key] = {'n': len(ts), 'p50_us': ts[len(ts) // 2] * 1e-3,
                    'p99_us': ts[int(0.99 * (len(ts) - 1))] * 1e-3,
                    'min_us': ts[0] * 1e-3}
    out['tracker_commands'] = tracker.commands
    out['loadavg'] = os.getloadavg()
    print(json.dumps(out))
    tracker.destroy_node()
    echo.destroy_node()
    rclpy.try_shutdown()
    return 0


def cmd_composed(args) -> int:
    from nonfragile_tracker.workflows import runner
    params = runner.scenario_parameters(Path(args.scenario), Path(args.gains), {
        'plant': {'ros__parameters': {'duration': float(args.duration)}}})
    t0 = time.monotonic()
    res = runner.run_composed(params, None, record=False, timeout=args.timeout)
    print(json.dumps({'wall_s': res.wall_time, 'total_s': time.monotonic() - t0,
                      'codes': res.exit_codes, 'steps': res.steps}), flush=True)
    return 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest='cmd', required=True)
    p = sub.add_parser('probe')
    p.add_argument('--namespaces', default='', help="comma list ('' = root namespace)")
    p.add_argument('--pids', default='', help='comma list of pids to sample CPU time of')
    p.add_argument('--wait', type=float, default=20.0, help='max wait for the first odom (s)')
    p.add_argument('--warmup', type=float, default=1.0)
    p.add_argument('--duration', type=float, default=5.0)
    p.add_argument('--no-cmd', action='store_true', help='subscribe odom only')
    # the EventsExecutor of rclpy 7.1 raises SystemError for (msg, info) callbacks
    p.add_argument('--executor', choices=['events', 'single'], default='single')
    p.add_argument('--out', required=True)
    p.set_defaults(func=cmd_probe)
    q = sub.add_parser('publish')
    q.add_argument('--topic', default='odom', help='topic name (topics.ODOM of the package)')
    q.add_argument('--rate', type=float, required=True)
    q.add_argument('--count', type=int, required=True)
    q.add_argument('--wait', type=float, default=20.0)
    q.set_defaults(func=cmd_publish)
    e = sub.add_parser('echo')
    e.add_argument('--ns', default='', help="node namespace ('' = root)")
    e.set_defaults(func=cmd_echo)
    b = sub.add_parser('callback')
    b.add_argument('--params', required=True, help='parameter file (realtime tracker)')
    b.add_argument('--calls', type=int, default=5000)
    b.add_argument('--warmup', type=int, default=500)
    b.set_defaults(func=cmd_callback)
    c = sub.add_parser('composed')
    c.add_argument('--duration', type=float, required=True)
    c.add_argument('--scenario', required=True)
    c.add_argument('--gains', required=True)
    c.add_argument('--timeout', type=float, default=300.0)
    c.set_defaults(func=cmd_composed)
    args = ap.parse_args(argv)
    return args.func(args)


if __name__ == '__main__':
    sys.exit(main())
