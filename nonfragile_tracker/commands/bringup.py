"""``bringup``: one command from a new robot to a certified tracker (the bring-up node).

Plans the excitation (``--dry-run`` prints its extent and ends without ROS), then starts
the bring-up node process (:mod:`nonfragile_tracker.nodes.bringup`) on the robot's
topics and waits for it, passing Ctrl-C and SIGTERM on (the node commands zero and
ends).  ``--simulate SCENARIO`` starts the package's plant in real time with the
scenario's plant parameters first (no robot needed).

See doc/cli.md, section "bringup", and doc/tutorial.md, section "One command (bringup)".
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import signal
import sys
import time
from pathlib import Path
from typing import Any

from ..errors import EXIT_INTERRUPTED, EXIT_RUN, InputError
from ..interface import topics
from .argtypes import positive_float
from .common import Subparsers

__all__ = ['register', 'cmd_bringup']

#: How long the node may take to end after the stop was passed on (s) before it is killed.
STOP_WAIT_S = 10.0


def cmd_bringup(args: argparse.Namespace) -> int:
    """Plan (and with ``--dry-run`` only print) the excitation, then run the bring-up node.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line of ``bringup``.
    """
    from ..workflows.commissioning import bringup_limits
    from ..interface.robot import RobotConfig, load_robot_file
    from ..control.identification.excitation import plan_excitation
    from ..interface.resources import config_dir
    robot = load_robot_file(args.robot) if args.robot else RobotConfig()   # '': none
    v, w = bringup_limits(robot, args.max_speed, args.max_turn_rate)
    plan = plan_excitation(args.box, v, w, accel_segment=args.accel_segment,
                           odom_rate=args.odom_rate, max_linear_accel=robot.max_linear_accel,
                           max_angular_accel=robot.max_angular_accel, duration=args.duration)
    ext = plan.extent()
    print(f'excitation (at {args.odom_rate:g} Hz odometry): {ext.describe()}')
    print(f'box {args.box:g} m around the start pose; limits |v| <= {v:g} m/s, |w| <= {w:g} '
          f'rad/s; {len(plan.segments)} segments'
          f'{", with the acceleration segment" if args.accel_segment else ""}; then the '
          f'identification, the design and a {args.trial_duration:g} s trial')
    for note in plan.notes:
        print(f'note: {note}')
    if args.dry_run:
        for name, t0, t1 in plan.segments:
            print(f'  {t0:6.1f} - {t1:6.1f} s  {name}')
        print('dry run: nothing moved')
        return 0
    from ..workflows import runner
    from ..bag.writer import new_run_dir
    gains = Path(args.gains) if args.gains else config_dir() / 'tracker_gains.yaml'
    problem = Path(args.problem) if args.problem else config_dir() / 'paper_problem.yaml'
    for what, path in (('--gains', gains), ('--problem', problem)):
        if not path.is_file():
            raise InputError(f'{what}: no such file {path}')
    run_dir = new_run_dir(Path(args.out), args.name)
    print(f'run directory: {run_dir}')
    params = {'bringup': {'ros__parameters': {
        'run_dir': str(run_dir.resolve()), 'box_radius': float(args.box),
        'max_linear_speed': float(v), 'max_angular_speed': float(w),
        'accel_segment': bool(args.accel_segment),
        'excitation_duration': float(args.duration),
        'trial_duration': float(args.trial_duration),
        'odom_timeout': float(args.odom_timeout if args.odom_timeout is not None
                              else robot.input_timeout),
        'gains': str(gains.resolve()), 'problem': str(problem.resolve()),
        'truth_topic': args.truth if args.truth is not None else
        (topics.POSE if args.simulate else ''),
        'robot': json.dumps(dataclasses.asdict(robot))}}}
    if args.simulate:
        plant = runner.scenario_parameters(Path(args.simulate), None).get('plant', {}).get(
            'ros__parameters', {})
        plant.update(mode='realtime', duration=0.0, enable_stamped_cmd_vel=
                     robot.enable_stamped_cmd_vel)
        params['plant'] = {'ros__parameters': plant}
    params_file = runner.write_parameter_file(params, run_dir / 'params.yaml')
    if not args.simulate:                    # a real robot: the caller's domain
        return _run_nodes(params_file, run_dir, robot, None, False)
    with runner.reserved_domain() as env:    # the simulated base on a domain of its own
        return _run_nodes(params_file, run_dir, robot, env, True)


def _run_nodes(params_file: Path, run_dir: Path, robot: Any, env: dict[str, str] | None,
               simulate: bool) -> int:
    """Run the bring-up node (and with ``simulate`` the simulated plant) to its end.

    SIGINT and SIGTERM are passed on to the node, which commands zero and ends; a process
    that does not end within :data:`STOP_WAIT_S` is killed after its stacks are asked for
    (:class:`~nonfragile_tracker.workflows.runner.NodeProcess`).  Returns the node's exit code
    (:data:`EXIT_INTERRUPTED` if stopped before it started or if it ended 0 after a stop;
    :data:`EXIT_RUN` if the simulated plant ended first).
    """
    from ..workflows.runner import NodeProcess
    procs: dict[str, NodeProcess] = {}
    signals: list[int] = []

    def forward(signum: int, frame: object) -> None:
        signals.append(signum)
        node = procs.get('bringup')
        if node is not None:
            node.interrupt(signum)

    previous = {s: signal.signal(s, forward) for s in (signal.SIGINT, signal.SIGTERM)}
    code: int | None = EXIT_INTERRUPTED            # stopped before the node started
    try:
        if simulate:
            procs['plant'] = NodeProcess(
                'plant', params_file, run_dir / 'plant.log', env,
                ['-r', f'odom:={robot.odom_topic}', '-r', f'cmd_vel:={robot.cmd_vel_topic}'])
        if not signals:
            procs['bringup'] = NodeProcess('bringup', params_file, None, env)
        node = procs.get('bringup')
        while node is not None and not node.wait(0.1):
            plant = procs.get('plant')
            if plant is not None and plant.poll() is not None and not signals:
                print(f'error: the simulated plant ended (code {plant.poll()}); see '
                      f'{run_dir / "plant.log"}', file=sys.stderr)
                code = EXIT_RUN
                break
        else:
            if node is not None:
                code = node.poll()
    finally:
        deadline = time.monotonic() + STOP_WAIT_S
        for name in ('bringup', 'plant'):          # the node first: it commands zero
            p = procs.get(name)
            if p is not None:
                p.stop(max(deadline - time.monotonic(), 0.5))
                p.close()
        for s, h in previous.items():
            signal.signal(s, h)
    if signals and code == 0:
        return EXIT_INTERRUPTED
    return int(code or 0)


def register(subparsers: Subparsers) -> None:
    """Add ``bringup`` to the CLI.

    Parameters
    ----------
    subparsers : argparse._SubParsersAction
        The CLI's sub-commands (``cli.build_parser``); ``bringup`` is added to them.
    """
    p = subparsers.add_parser(
        'bringup', help='one command from a new robot to a certified tracker: excite, '
        'identify, design, verify',
        description='Drive a designed excitation within a box around the start pose '
        '(closed loop, the shipped certified gain), record commands and odometry, identify '
        'latency, lags and limits, design a gain certified for them, verify it in a short '
        'trial, and write the robot file, the gain file and a report into the run folder. '
        'Ctrl-C, SIGTERM, odometry silence, leaving the box and any error command zero '
        'velocity and end the run.  The box check uses the odometry (in the trial plus the '
        'side slip the tracker reckons): it does not protect against odometry drift or '
        'obstacles.')
    p.add_argument('--robot', metavar='FILE', help='robot file (ROS 2 parameter file with a '
                   '/**/tracker section: topics, frames, TwistStamped, limits); default: '
                   'odom, cmd_vel, Twist, no known limits')
    p.add_argument('--box', type=positive_float, default=1.0,
                   help='stay within this distance of the start pose (m, default 1)')
    p.add_argument('--max-speed', type=positive_float,
                   help='limit on |v| (m/s; default 0.3, or the robot file\'s if lower)')
    p.add_argument('--max-turn-rate', type=positive_float,
                   help='limit on |w| (rad/s; default 1, or the robot file\'s if lower)')
    p.add_argument('--accel-segment', action=argparse.BooleanOptionalAction, default=True,
                   help='end the excitation with steps faster than the base follows, so '
                   'that its acceleration limits bind and are identified (default; '
                   '--no-accel-segment: every ramp gentle, the limits not identified)')
    p.add_argument('--duration', type=positive_float, default=55.0,
                   help='robot time of the excitation (s, default 55)')
    p.add_argument('--trial-duration', type=float, default=20.0,
                   help='robot time of the trial with the designed gain (s, default 20; 0: '
                   'none)')
    p.add_argument('--odom-rate', type=positive_float, default=50.0,
                   help='--dry-run: the odometry rate to plan for (Hz; a run measures it)')
    p.add_argument('--odom-timeout', type=positive_float,
                   help='stop if the odometry is silent this long (s; default the robot '
                   'file\'s input_timeout, 0.5)')
    p.add_argument('--gains', help='gain of the excitation (default config/tracker_gains.yaml, '
                   'certified up to 0.15 s of latency through a 50 ms lag)')
    p.add_argument('--problem', help='problem file of the design (default '
                   'config/paper_problem.yaml)')
    p.add_argument('--dry-run', action='store_true',
                   help='plan the excitation, print its extent and segments, move nothing')
    p.add_argument('--simulate', metavar='SCENARIO',
                   help="start this package's plant in real time with the scenario's plant "
                   'parameters (no robot needed), e.g. config/latency_scenario.yaml')
    p.add_argument('--truth', metavar='TOPIC', help='an external pose of the base '
                   '(geometry_msgs/PoseStamped: motion capture) recorded beside the odometry: '
                   'the side slip the odometry does not see is identified from it and '
                   'compensated (default with --simulate: the plant\'s true pose, pose; '
                   'otherwise none; "" = none)')
    p.add_argument('--out', default='runs', help='directory for run directories (default runs/)')
    p.add_argument('--name', help='run directory name (default run_<date>_<time>)')
    p.set_defaults(func=cmd_bringup)
