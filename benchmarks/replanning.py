"""Issue 41: a lap followed while a planner republishes it every second, against the lap given once.

A planner stand-in (Nav2's ``planner_server`` republishes its ``nav_msgs/Path``, untimed, about
every second) sends the rest of the lap every 1 s: from 0.2 m behind the robot (a plan that
starts behind it), resampled at a new 5 cm spacing each time, with a smooth lateral change of
up to ``--wiggle`` (5 mm) - small changes, as a replanning planner makes.  Three cases, each
through the tracker's input rules (:class:`nonfragile_tracker.interface.tracker_inputs.TrackerInputs`,
what the node runs) on the unicycle at 50 Hz, ``cruise_speed`` 0.4 m/s, ``max_accel`` 0.5
m/s^2:

* ``once``: the lap given once (one untimed Path at the start);
* ``replanned``: the plans spliced onto the motion (``replan: true``, the default);
* ``unchanged``: the same, with plans that do not change (``--wiggle`` 0; still resampled and
  starting behind the robot): what the splicing itself costs;
* ``new runs``: the same plans, each a new run from rest (``replan: false``, the behaviour
  before issue 41).

Figures: cross-track error against the lap (RMS and max, while driving: after the first
metre, before the last), the speed dips (the largest shortfall of the speed below the once
run's at the same place along the lap, and the lowest speed while cruising), the lap time.
Median of ``--seeds`` (3) planner seeds.  ``--ros``: one more run of ``replanned`` through the
tracker node in lockstep (a planner node and a base in one process, DDS in between), compared
with the in-process run of the same seed.

Usage::

    PYTHONPATH=$PWD .venv/bin/python benchmarks/replanning.py [--seeds 3] [--ros] [--json F]
"""
from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import sys
import time
from pathlib import Path as FsPath
from typing import Any, Callable

import numpy as np

ROOT = FsPath(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from geometry_msgs.msg import PoseStamped  # noqa: E402
from nav_msgs.msg import Odometry, Path  # noqa: E402

from nonfragile_tracker.control.simulation.gains import read_gain_file  # noqa: E402
from nonfragile_tracker.control.simulation.tracker import Command
from nonfragile_tracker.control.simulation.plant import PlantConfig
from nonfragile_tracker.control.simulation.timing import step_time_ns
from nonfragile_tracker.control.simulation.replan import nearest_point  # noqa: E402
from nonfragile_tracker.control.simulation.simulate import run_loop  # noqa: E402
from nonfragile_tracker.control.simulation.trajectory import load_waypoints  # noqa: E402
from nonfragile_tracker.interface.msgconv import fill_pose, ns_to_stamp, tracker_config  # noqa: E402
from nonfragile_tracker.interface.tracker_inputs import TrackerInputs, input_rules  # noqa: E402

DT = 0.02
SECONDS = 26.0
PERIOD = 1.0
GAINS = ROOT / 'config' / 'tracker_gains.yaml'


def parameters(replan: bool = True) -> dict[str, Any]:
    """The tracker's parameters in every case (node and in process alike)."""
    return {'K': [float(v) for v in read_gain_file(GAINS).ravel()], 'mode': 'lockstep',
            'wait_for_trajectory': True, 'cruise_speed': 0.4, 'max_accel': 0.5,
            'replan': replan, 'monitor': False}


def lap(step: float = 0.05) -> tuple[np.ndarray, np.ndarray]:
    """config/trajectories/lap.csv's path (2 m straights, 0.3 m turns), every ``step`` m.

    The file's spline (its points are 10 cm apart and turn in few of them) sampled finely,
    then by arc length: the smooth path a planner's 5 cm grid would follow.
    """
    traj = load_waypoints(ROOT / 'config' / 'trajectories' / 'lap.csv')
    fine = traj.evaluate(np.linspace(traj.t_start, traj.t_end, 20001))
    x, y = fine.x, fine.y
    keep = np.concatenate([[True], np.hypot(np.diff(x), np.diff(y)) > 0])
    x, y = x[keep], y[keep]
    s = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(x), np.diff(y)))])
    ss = np.append(np.arange(0.0, s[-1], step), s[-1])
    return np.interp(ss, s, x), np.interp(ss, s, y)


def path_msg(x: np.ndarray, y: np.ndarray) -> Path:
    """An untimed nav_msgs/Path (header stamp 0: the receiver's now) in odom."""
    msg = Path()
    msg.header.frame_id = 'odom'
    yaw = np.arctan2(np.gradient(y), np.gradient(x))
    for a, b, c in zip(x, y, yaw):
        ps = PoseStamped()
        ps.header.frame_id = 'odom'
        fill_pose(ps.pose, float(a), float(b), float(c))
        msg.poses.append(ps)
    return msg


class Planner:
    """The planner stand-in: every ``period`` s the rest of the lap, changed a little."""

    def __init__(self, px: np.ndarray, py: np.ndarray, seed: int, *, period: float = PERIOD,
                 wiggle: float = 0.005, behind: float = 0.2):
        self.px, self.py = px, py
        self.s = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(px), np.diff(py)))])
        self.rng = np.random.default_rng(seed)
        self.every = int(round(period / DT))
        self.wiggle, self.behind = wiggle, behind
        self.done = 0.0                 # progress along the lap (its end meets its start)

    def __call__(self, k: int, x: float, y: float) -> Path | None:
        """The plan to publish before odometry step ``k`` (the robot at ``x, y``), or None."""
        if k == 0:
            return path_msg(self.px, self.py)
        if k % self.every:
            return None
        s = self.s
        i = min(max(int(np.searchsorted(s, self.done, side='right')) - 1, 0), s.size - 2)
        self.done = s[i] + nearest_point(self.px[i:], self.py[i:], x, y,
                                         search_distance=1.0).s
        start = max(self.done - self.behind, 0.0)
        if s[-1] - start < 0.3:
            return None                 # at the goal: nothing more to plan
        ss = np.append(np.arange(start + self.rng.uniform(0.0, 0.05), s[-1], 0.05), s[-1])
        x2, y2 = np.interp(ss, s, self.px), np.interp(ss, s, self.py)
        bump = self.wiggle * math.sin(self.rng.uniform(0.0, math.tau)) * np.sin(ss)
        nx, ny = -np.gradient(y2), np.gradient(x2)
        nrm = np.hypot(nx, ny)
        return path_msg(x2 + bump * nx / nrm, y2 + bump * ny / nrm)


def odom_msg(ns: int, x: float, y: float, th: float, v: float) -> Odometry:
    """The odometry of one step (pose in odom, ``twist.linear.x`` the speed)."""
    m = Odometry()
    m.header.frame_id = 'odom'
    ns_to_stamp(ns, m.header.stamp)
    fill_pose(m.pose.pose, x, y, th)
    m.twist.twist.linear.x = v
    return m


def in_process(plans: Callable[[int, float, float], Path | None], replan: bool = True,
               plant: PlantConfig | None = None) -> dict[str, np.ndarray]:
    """The lap through the tracker's input rules on the unicycle; the samples.

    ``cmd`` (time, v, w of each command) and ``odom`` (stamp, v, w of each odometry) are
    what the certificate monitor reads.
    """
    from nonfragile_tracker.nodes.tracker import MONITOR_PARAMS, PARAMS
    values = {**{p.name: p.default for p in PARAMS + MONITOR_PARAMS}, **parameters(replan)}
    inputs = TrackerInputs(tracker_config(values), input_rules(values))

    cmds: list[tuple[float, float, float]] = []
    odoms: list[tuple[float, float, float]] = []

    def command(meas: Any, th: float, k: int, ref: Any) -> Command:
        msg = plans(k, meas.x, meas.y)
        if msg is not None:
            inputs.trajectory(msg, 'path', 'topic /trajectory', defer=True)
        ns = step_time_ns(meas.step, DT)
        step = inputs.odom(odom_msg(ns, meas.x, meas.y, th, meas.v))
        c = step.command if step is not None else Command(0.0, 0.0)
        odoms.append((ns * 1e-9, meas.v, meas.w))
        cmds.append((k * DT, c.v, c.w))
        return c

    run = run_loop(plant or PlantConfig(dt=DT), int(SECONDS / DT), command, _no_reference)
    return {'t': run.t, 'x': run.x, 'y': run.y, 'v': run.speed, 'cmd_v': run.cmd_v,
            'splices': np.array(inputs.splices), 'cmd': np.array(cmds),
            'odom': np.array(odoms)}


#: A base like the shipped gain's certificate assumes: 100 ms command latency, 50 ms lags.
LATENCY_BASE = PlantConfig(dt=DT, cmd_latency=0.1, lag_v=0.05, lag_w=0.05)


def monitor_levels(run: dict[str, np.ndarray]) -> tuple[dict[str, int], float]:
    """The certificate monitor's verdicts over the run (every 1 s, 4 s windows) and the
    median latency estimate (s), against the shipped gain's certificate."""
    import yaml

    from nonfragile_tracker.control.identification.monitor import (MonitorSettings,
                                                                   certificate_from_parameters,
                                                                   estimate_latency, evaluate)
    sec = yaml.safe_load(GAINS.read_text())
    sec = next(iter(sec.values()))['ros__parameters']
    cert = certificate_from_parameters(sec['certified_residual'], sec['certified_lag'],
                                       sec.get('certified_adapt_range'), hold=DT)
    settings = MonitorSettings(max_linear_speed=1.0, max_angular_speed=2.0)
    c, o = run['cmd'], run['odom']
    levels: dict[str, int] = {}
    lat = []
    for t_end in np.arange(5.0, float(o[-1, 0]) + 1e-9, 1.0):
        est = estimate_latency(c[:, 0], c[:, 1], c[:, 2], o[:, 0], o[:, 1], o[:, 2],
                               settings, t_end=float(t_end))
        name = evaluate(est, cert, 0.0, settings).name
        levels[name] = levels.get(name, 0) + 1
        if est.valid:
            lat.append(est.latency)
    return levels, float(np.median(lat)) if lat else math.nan


def _no_reference(k: int) -> Any:
    from nonfragile_tracker.control.simulation.reference import RefSample
    return RefSample(k * DT, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)


def through_the_node(plans: Callable[[int, float, float], Path | None], domain_id: int
                     ) -> dict[str, np.ndarray]:
    """The same lap through the tracker node (lockstep; a planner and a base node, DDS)."""
    import rclpy
    from geometry_msgs.msg import Twist
    from rclpy.parameter import Parameter

    from nonfragile_tracker.interface import topics
    from nonfragile_tracker.control.simulation.plant import UnicyclePlant
    from nonfragile_tracker.nodes.common import DATA_QOS, LATCHED_QOS, make_executor
    from nonfragile_tracker.nodes.tracker import TrackerNode

    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=domain_id)
    tracker = TrackerNode(context=ctx, parameter_overrides=[
        Parameter(k, value=v) for k, v in parameters().items()])
    base = rclpy.create_node('base_and_planner', context=ctx)
    odom_pub = base.create_publisher(Odometry, topics.ODOM, DATA_QOS)
    plan_pub = base.create_publisher(Path, topics.TRAJECTORY, LATCHED_QOS)
    got: list[tuple[float, float]] = []
    base.create_subscription(Twist, topics.CMD_VEL,
                             lambda m: got.append((m.linear.x, m.angular.z)), DATA_QOS)
    ex = make_executor(ctx)
    ex.add_node(tracker)
    ex.add_node(base)

    def spin_until(done: Callable[[], bool], timeout: float = 10.0) -> bool:
        end = time.monotonic() + timeout
        while not done() and time.monotonic() < end:
            ex.spin_once(timeout_sec=0.01)
        return done()

    plant = UnicyclePlant(PlantConfig(dt=DT))
    rows = []
    try:
        assert spin_until(lambda: bool(odom_pub.get_subscription_count()
                                       and tracker.pub_cmd.get_subscription_count()
                                       and plan_pub.get_subscription_count()))
        for k in range(int(SECONDS / DT) + 1):
            meas = plant.odometry()
            msg = plans(k, meas.x, meas.y)
            if msg is not None:
                n_plans = tracker.inputs.splices + (tracker.inputs.follower is not None)
                plan_pub.publish(msg)
                assert spin_until(lambda: tracker.inputs.splices
                                  + (tracker.inputs.follower is not None) > n_plans)
            n = len(got)
            odom_pub.publish(odom_msg(step_time_ns(meas.step, DT), meas.x, meas.y,
                                      meas.th, meas.v))
            assert spin_until(lambda: len(got) > n), f'no command at step {k}'
            plant.command(*got[-1])
            rows.append((k * DT, plant.x, plant.y, plant.v, got[-1][0]))
            plant.advance()
        splices = tracker.inputs.splices
    finally:
        ex.shutdown()
        base.destroy_node()
        tracker.destroy_node()
        rclpy.try_shutdown(context=ctx)
    t, x, y, v, c = np.array(rows).T
    return {'t': t, 'x': x, 'y': y, 'v': v, 'cmd_v': c, 'splices': np.array(splices)}


def figures(run: dict[str, np.ndarray], once: dict[str, np.ndarray] | None,
            px: np.ndarray, py: np.ndarray) -> dict[str, float]:
    """Cross-track RMS / max (m), the largest speed dip (m/s), lowest cruising speed, lap time."""
    s_lap = float(np.sum(np.hypot(np.diff(px), np.diff(py))))
    near = [nearest_point(px, py, a, b, search_distance=1e9) for a, b in zip(run['x'],
                                                                              run['y'])]
    # progress along the lap, unwrapped (its end meets its start)
    prog = np.array([n.s for n in near])
    prog = np.maximum.accumulate(np.where(np.arange(prog.size) < prog.size // 4,
                                          np.minimum(prog, s_lap / 2), prog))
    e = np.array([n.distance for n in near])
    driving = (prog > 1.0) & (prog < s_lap - 1.0)
    out = {'cross_rms_mm': 1e3 * float(np.sqrt(np.mean(e[driving] ** 2))),
           'cross_max_mm': 1e3 * float(e[driving].max()),
           'min_speed': float(run['v'][driving].min()),
           'lap_time_s': _arrival(run, prog, s_lap),
           'plans_spliced': int(run['splices'])}
    if once is not None:
        f = figures(once, None, px, py)
        ref_v = np.interp(prog[driving], f['_prog'], f['_v'])
        out['speed_dip'] = float(np.max(ref_v - run['v'][driving]))
    out['_prog'] = prog[driving]        # type: ignore[assignment]
    out['_v'] = run['v'][driving]       # type: ignore[assignment]
    return out


def _arrival(run: dict[str, np.ndarray], prog: np.ndarray, s_lap: float) -> float:
    """When the robot is at rest within 2 cm of the lap's end (s); nan if never."""
    done = (prog > s_lap - 0.02) & (np.abs(run['v']) < 0.01)
    return float(run['t'][np.argmax(done)]) if done.any() else math.nan


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--seeds', type=int, default=3)
    ap.add_argument('--ros', action='store_true', help='also one run through the node')
    ap.add_argument('--wiggle', type=float, default=0.005,
                    help='largest lateral change of a plan (m)')
    ap.add_argument('--domain-id', type=int, default=215 + os.getpid() % 18,
                    help='ROS domain of the --ros run (default outside the tests\' 100..199)')
    ap.add_argument('--json', type=FsPath, default=None)
    args = ap.parse_args(argv)
    px, py = lap()
    once = in_process(lambda k, x, y: path_msg(px, py) if k == 0 else None)
    rows: dict[str, list[dict[str, float]]] = {'once': [], 'replanned': [], 'unchanged': [],
                                               'new runs': []}
    f_once = figures(once, None, px, py)
    once['_prog'], once['_v'] = f_once['_prog'], f_once['_v']       # type: ignore[assignment]
    t0 = time.perf_counter()
    for seed in range(args.seeds):
        rows['once'].append({**f_once, 'speed_dip': 0.0})
        for name, replan, wiggle in (('replanned', True, args.wiggle),
                                     ('unchanged', True, 0.0), ('new runs', False, args.wiggle)):
            run = in_process(Planner(px, py, seed, wiggle=wiggle), replan=replan)
            rows[name].append(figures(run, once, px, py))
    wall = time.perf_counter() - t0
    keys = ['cross_rms_mm', 'cross_max_mm', 'speed_dip', 'min_speed', 'lap_time_s',
            'plans_spliced']
    table = {name: {k: statistics.median(r[k] for r in rs) for k in keys}
             for name, rs in rows.items()}
    print(f'lap {float(np.sum(np.hypot(np.diff(px), np.diff(py)))):.2f} m, cruise 0.4 m/s, '
          f'plans every {PERIOD:g} s; median of {args.seeds} seeds ({wall:.1f} s)')
    print(f'{"case":<12}' + ''.join(f'{k:>15}' for k in keys))
    for name, row in table.items():
        print(f'{name:<12}' + ''.join(f'{row[k]:>15.4g}' for k in keys))
    result: dict[str, Any] = {'median': table, 'runs': {n: [{k: r[k] for k in keys}
                                                           for r in rs]
                                                       for n, rs in rows.items()}}
    # the certificate monitor on a base with latency and lag: replans must not disturb it
    for name, plans in (('once', lambda k, x, y: path_msg(px, py) if k == 0 else None),
                        ('replanned', Planner(px, py, 0, wiggle=args.wiggle))):
        levels, lat = monitor_levels(in_process(plans, plant=LATENCY_BASE))
        print(f'monitor, {name:<9} (100 ms latency, 50 ms lags): verdicts '
              f'{dict(sorted(levels.items()))}, latency estimate {1e3 * lat:.1f} ms')
        result.setdefault('monitor', {})[name] = {'verdicts': levels, 'latency_s': lat}
    if args.ros:
        t1 = time.perf_counter()
        node = through_the_node(Planner(px, py, 0), args.domain_id)
        same = in_process(Planner(px, py, 0))
        fn = figures(node, once, px, py)
        dx = float(np.max(np.hypot(node['x'] - same['x'], node['y'] - same['y'])))
        print(f'{"node (ROS)":<12}' + ''.join(f'{fn[k]:>15.4g}' for k in keys)
              + f'   (seed 0; {time.perf_counter() - t1:.1f} s; largest distance to the '
              f'in-process run {dx:.2e} m)')
        result['ros'] = {**{k: fn[k] for k in keys}, 'max_distance_to_in_process_m': dx}
    if args.json:
        args.json.write_text(json.dumps(result, indent=2))
    return 0


if __name__ == '__main__':
    sys.exit(main())
