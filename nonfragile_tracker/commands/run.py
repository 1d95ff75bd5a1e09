"""``run``: the main job - the scenario through the ROS nodes, a bag, a report and plots.

See doc/cli.md, section "run".
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from ..errors import EXIT_BAD_INPUT, EXIT_RUN, InputError
from .argtypes import positive_float
from .common import Subparsers

__all__ = ['register', 'cmd_run']


def _last_error(log: Path) -> str:
    """The last FATAL/ERROR line of a node's log (without the logger prefix), or a pointer."""
    try:
        lines = log.read_text(errors='replace').splitlines()
    except OSError:
        return f'no log ({log})'
    for line in reversed(lines):
        if 'FATAL' in line or 'ERROR' in line:
            return line.split('] ', 1)[-1].strip() if '] ' in line else line.strip()
    return f'exited with bad input; see {log}'


def cmd_run(args: argparse.Namespace) -> int:
    """Run the scenario (one process per node or composed), then report on its bag.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line of ``run``.
    """
    from ..workflows import runner
    from ..bag.writer import new_run_dir
    from ..control.simulation.gains import read_gain_file
    from ..interface.resources import config_dir
    if args.paper and (args.gains or args.delay_compensation):
        raise InputError('--paper is the paper\'s configuration (its K_nf, no delay '
                         'compensation): leave out --gains and --delay-compensation')
    if args.robot:
        from ..control.simulation.physics import BASES
        if args.scenario:
            raise InputError('--robot NAME runs that physics base\'s scenario '
                             '(config/bases/NAME.yaml): leave out --scenario')
        if args.robot not in BASES:
            raise InputError(f'--robot {args.robot}: not a physics base; choose one of '
                             f'{", ".join(sorted(BASES))}')
        args.scenario = str(config_dir() / 'bases' / f'{args.robot}.yaml')
        args.record_all = True          # the true pose (topic pose) beside the odometry
    scenario = Path(args.scenario) if args.scenario else config_dir() / 'paper_scenario.yaml'
    gains = (Path(args.gains) if args.gains else config_dir() / (
        'paper_gains_tracker.yaml' if args.paper else 'tracker_gains.yaml'))
    ov: dict[str, dict[str, dict[str, Any]]] = {
        'plant': {'ros__parameters': {}}, 'tracker': {'ros__parameters': {}},
        'reference': {'ros__parameters': {}}}
    if args.duration is not None:
        ov['plant']['ros__parameters']['duration'] = float(args.duration)
    if args.delta:
        from ..interface.scenario import paper_perturbations
        deltas = paper_perturbations()          # config/paper_problem.yaml perturbations
        if args.delta not in deltas:
            raise InputError(f'--delta {args.delta}: not a perturbation of the paper problem; '
                             f'choose one of {", ".join(sorted(deltas))}')
        ov['tracker']['ros__parameters']['Delta'] = deltas[args.delta]
    if args.delay_compensation:
        ov['tracker']['ros__parameters']['delay_compensation'] = True
    if args.path:
        ov['reference']['ros__parameters']['path'] = args.path
    if args.stamped_cmd_vel:
        for node in ('tracker', 'plant', 'recorder'):
            ov.setdefault(node, {'ros__parameters': {}})['ros__parameters'][
                'enable_stamped_cmd_vel'] = True
    if args.trajectory:
        from ..control.simulation.trajectory import load_waypoints
        traj = load_waypoints(args.trajectory)      # refuse a bad file before starting (2)
        start = traj.sample(traj.t_start)
        ov['reference']['ros__parameters']['trajectory_file'] = str(Path(args.trajectory)
                                                                    .resolve())
        ov['tracker']['ros__parameters']['wait_for_trajectory'] = True
        ov['plant']['ros__parameters'].update(initial_pose=[start.x, start.y, start.heading],
                                              initial_speed=0.0)
        if args.duration is None:
            ov['plant']['ros__parameters']['duration'] = round(traj.t_end + 3.0, 2)
    params = runner.scenario_parameters(scenario, gains, ov)
    read_gain_file(gains)           # refuse a bad gain before starting anything (exit 2)
    run_dir = new_run_dir(Path(args.out), args.name)
    record = not args.no_record
    dur = params['plant']['ros__parameters'].get('duration')
    print(f'run directory: {run_dir}')
    length = f'{dur:g} s simulated' if dur is not None else "the plant's default duration"
    comp = params['tracker']['ros__parameters'].get('delay_compensation', False)
    print(f'scenario {scenario.name}, gains {gains.name}'
          f'{", delay compensation" if comp else ""}, {length}, '
          f'{"composed" if args.composed else "one process per node"}, lockstep')
    if args.composed:
        res = runner.run_composed(params, run_dir, record=record, record_all=args.record_all)
    else:
        res = runner.run_processes(params, run_dir, record=record, record_all=args.record_all)
    bad = {k: v for k, v in res.exit_codes.items() if v not in (0, None, -2)}
    if bad and all(code == EXIT_BAD_INPUT for code in bad.values()):
        # every failed node refused its parameters: bad input, say which and why
        for node in bad:
            print(f'error: {node}: {_last_error(run_dir / f"{node}.log")}', file=sys.stderr)
        return EXIT_BAD_INPUT
    print(f'wall time {res.wall_time:.1f} s ({res.steps / max(res.wall_time, 1e-9):.0f} steps/s '
          'including start-up)')
    if bad:
        print(f'error: node(s) failed: {bad}; logs in {run_dir}', file=sys.stderr)
        return EXIT_RUN
    if res.bag is not None:                      # set exactly when the run recorded
        from ..bag.report import bag_report, format_report
        rep = bag_report(res.bag, run_dir)
        print(format_report(rep))
        print(f'bag: {res.bag}\nplots and summary: {run_dir}')
    return 0


def register(subparsers: Subparsers) -> None:
    """Add ``run`` to the CLI.

    Parameters
    ----------
    subparsers : argparse._SubParsersAction
        The CLI's sub-commands (``cli.build_parser``); ``run`` is added to them.
    """
    r = subparsers.add_parser('run', help='the main job: paper scenario through the ROS nodes, '
                       'bag, report and plots')
    r.add_argument('--scenario', help='node parameter file (default config/paper_scenario.yaml)')
    r.add_argument('--robot', metavar='NAME',
                   help='a MuJoCo base of config/bases (turtlebot3, jackal, jackal_skid): its '
                   'scenario (a figure eight, 40 ms latency, 50 Hz odometry), every topic '
                   'recorded (the true pose beside the odometry); needs mujoco-core')
    r.add_argument('--gains', help='tracker gain file (default config/tracker_gains.yaml: '
                   'certified for command latency up to 0.15 s through a 50 ms lag; '
                   'config/max_decay_gains.yaml: fastest on ideal plants, lockstep; after '
                   'the bring-up: the file latency-design wrote for your base)')
    r.add_argument('--duration', type=positive_float,
                   help='simulated seconds (default: scenario, 60)')
    r.add_argument('--delta', metavar='NAME',
                   help="inject a perturbation of config/paper_problem.yaml (Delta_1, Delta_2) "
                   'into the tracker as E Delta F')
    r.add_argument('--delay-compensation', action='store_true',
                   help='zero steady-state error law (delay-consistent reference); '
                   '`make demo` adds it (the recommended configuration)')
    r.add_argument('--paper', action='store_true',
                   help="the paper's configuration: its printed K_nf "
                   '(config/paper_gains_tracker.yaml), no delay compensation')
    r.add_argument('--path', choices=['circle', 'figure_eight'],
                   help="reference path (default: the scenario's reference path; "
                   'config/paper_scenario.yaml: circle)')
    r.add_argument('--trajectory', metavar='FILE',
                   help='follow a waypoint file (CSV/YAML: t, x, y[, yaw][, speed]) instead of '
                   'the path; the robot starts at its first pose, duration = its end + 3 s')
    r.add_argument('--stamped-cmd-vel', action='store_true',
                   help='cmd_vel as TwistStamped (enable_stamped_cmd_vel in tracker, plant, '
                   'recorder)')
    r.add_argument('--composed', action='store_true',
                   help='all nodes in this process (default: one process per node)')
    r.add_argument('--out', default='runs', help='directory for run directories (default runs/)')
    r.add_argument('--name', help='run directory name (default run_<date>_<time>)')
    r.add_argument('--no-record', action='store_true', help='do not record a bag')
    r.add_argument('--record-all', action='store_true',
                   help='record every topic (also /clock, pose and the per-step reference '
                        'samples); default: the lean set - odom, cmd_vel, run_done and the '
                        'trajectory messages')
    r.set_defaults(func=cmd_run)
