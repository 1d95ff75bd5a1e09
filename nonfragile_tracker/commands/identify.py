"""``identify BAG``: command-to-motion latency and actuator lags from a recorded run.

See doc/cli.md, section "identify", and doc/tutorial.md, section "Identify the latency
(``identify``)".
"""
from __future__ import annotations

import argparse
import math
from typing import TYPE_CHECKING

from .common import Subparsers, check_outputs, check_robot_file, write_robot_file

if TYPE_CHECKING:
    from ..bag.motion import MotionData
    from ..control.identification.identify import Identification

__all__ = ['register', 'cmd_identify']


def _fmt_interval(lo: float, hi: float) -> str:
    return f'[{lo:.4f}, {hi:.4f}]'


def cmd_identify(args: argparse.Namespace) -> int:
    """Read the bag, identify, print the estimates and the next step, optionally write -o.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line of ``identify``.
    """
    from ..bag.motion import read_motion
    from ..control.identification.identify import (identify_latency, measurement_to_command_delay,
                                    with_source, write_identification)
    check_outputs(args.force, args.output)
    check_robot_file(args.robot_file)
    data = read_motion(args.bag, cmd_topic=args.cmd_topic, odom_topic=args.odom_topic,
                       cmd_time=args.cmd_time)
    res = identify_latency(data.commands, data.odometry, max_latency_s=args.max_latency,
                           max_tau_s=args.max_tau, source=args.source,
                           confidence=args.confidence, bootstrap=args.bootstrap,
                           command_timeout_s=args.command_timeout, seed=args.seed)
    res = with_source(res, args.bag)
    cmd_period = res.command_period_s
    pct = f'{100 * res.confidence:.0f} %'
    src = {'twist': 'odometry twist', 'pose': 'differenced poses'}
    lines = [
        f'bag {args.bag}: commands {data.cmd_topic} ({data.cmd_type.split("/")[-1]}, by '
        f'{data.cmd_time}, {len(data.commands)} messages, period {cmd_period:.4g} s); '
        f'odometry {data.odom_topic} ({res.odom_rate_hz:.4g} Hz by {data.odom_time}, '
        f'{res.samples} samples fitted over {res.duration_s:.1f} s)',
        f'latency  L     = {res.latency_s:.4f} s   {pct} interval '
        f'{_fmt_interval(res.latency_low_s, res.latency_high_s)} s   (uncertainty of the '
        'mean latency)',
        f'latency range    {_fmt_interval(*res.latency_range_s)} s   (what the latency varies '
        f'over, from {res.latency_range_from}; latency-design certifies this range)',
        f'lag of v tau_v = {res.tau_v_s:.4f} s   {pct} interval '
        f'{_fmt_interval(res.tau_v_low_s, res.tau_v_high_s)} s   (from {src[res.source_v]}; '
        f'gain {res.gain_v:.3f}, residual rms {res.residual_rms_v:.3g} m/s, '
        f'explains {100 * res.r2_v:.1f} %)',
        f'lag of w tau_w = {res.tau_w_s:.4f} s   {pct} interval '
        f'{_fmt_interval(res.tau_w_low_s, res.tau_w_high_s)} s   (from {src[res.source_w]}; '
        f'gain {res.gain_w:.3f}, residual rms {res.residual_rms_w:.3g} rad/s, '
        f'explains {100 * res.r2_w:.1f} %)',
        f'each channel alone: latency {res.latency_v_s:.4f} s (v), {res.latency_w_s:.4f} s (w)',
        _limits_line(res),
    ]
    if res.commands_follow_odometry is not None:
        lines.append('commands: ' + ('computed from the odometry (a tracker)'
                                     if res.commands_follow_odometry else
                                     'not driven by the odometry (a joystick or script): '
                                     'their odometry age is not counted'))
    mc_delay = measurement_to_command_delay(data.commands, data.odometry)
    if math.isfinite(mc_delay[1]):
        lines.append(f'age of the newest odometry when a command is sent: median '
                     f'{mc_delay[1]:.4f} s (1-99 %: {mc_delay[0]:.4f} ... {mc_delay[2]:.4f} s)')
    if math.isfinite(data.odom_delay_s):
        lines.append(f'odometry transport delay (bag receive time - header stamp): median '
                     f'{data.odom_delay_s:.4f} s')
        if data.odom_delay_s < -1e-3 or data.odom_delay_s > 0.5:
            lines.append('warning: odometry stamps and bag times disagree by more than '
                         'transport would explain; if the robot and the recorder clocks are '
                         'not synchronized, the latency includes their offset')
    for note in res.notes:
        lines.append(f'note: {note}')
    if args.cross_check and 'twist' in (res.source_v, res.source_w):
        lines += _cross_check(args, data, res)
    if args.truth:
        res, slip_line = _side_slip(args, data, res)
        lines.append(slip_line)
    print('\n'.join(lines))
    if args.output:
        write_identification(args.output, res, overwrite=True)
        print(f'wrote {args.output}')
    if args.robot_file:
        from ..interface.robot import identified_limits
        write_robot_file(args.robot_file, identified_limits(res), f'identified from {args.bag}')
    from ..control.synthesis.latency_design import plan_from_identification
    if math.isfinite(res.command_period_s):
        plan = plan_from_identification(res)
        bare = plan_from_identification(res, predictor=False)
        out = args.output or 'FILE'
        print('next: gains certified for the residual delay after the tracker\'s predictor '
              '(docs: tutorial, "From the range to h_min, h_max"):\n'
              f'  nonfragile_tracker latency-design PROBLEM --identification {out} -o g.yaml\n'
              f'  = --delay-interval {plan.h_min:.4f} {plan.h_max:.4f} --lag {plan.lag:.4f} '
              f'with predict_latency {plan.predict_latency:.4f}, predict_odom_latency '
              f'{plan.predict_odom_latency:.4f}, predict_lag_v {plan.predict_lag_v:.4f}, '
              f'predict_lag_w {plan.predict_lag_w:.4f}, max_linear_accel '
              f'{plan.max_linear_accel:.4g}, max_angular_accel {plan.max_angular_accel:.4g} '
              '(written into g.yaml)\n'
              f'  without the predictor (--no-predictor): --delay-interval {bare.h_min:.4f} '
              f'{bare.h_max:.4f} --lag {bare.lag:.4f}')
    return 0


def _side_slip(args: argparse.Namespace, data: MotionData, res: Identification
               ) -> tuple[Identification, str]:
    """The side slip from ``--truth`` (the identification with its table when it matters)."""
    from ..workflows.commissioning import side_slip_from_truth
    res, line = side_slip_from_truth(args.bag, res, args.truth, odometry=data.odometry,
                                     strict=True)
    if not res.side_slip:
        return res, line
    rates = ', '.join(f'{r:g}' for r in res.side_slip_rates)
    coefs = ', '.join(f'{c:.4g}' for c in res.side_slip)
    return res, (line + f'\n  tracker: side_slip_rates [{rates}], side_slip [{coefs}] (in -o, '
                 'and latency-design --identification writes them into the gain file)')


def _limits_line(res: Identification) -> str:
    parts = []
    for name, a, frac, unit in (('max_linear_accel', res.max_linear_accel, res.accel_binding_v,
                                 'm/s^2'),
                                ('max_angular_accel', res.max_angular_accel,
                                 res.accel_binding_w, 'rad/s^2')):
        parts.append(f'{name} {a:.3g} {unit} (binding {100 * frac:.0f} % of the time)'
                     if a > 0 else f'{name} 0 (no limit seen to bind: unknown)')
    return 'acceleration limits: ' + ', '.join(parts)


def _cross_check(args: argparse.Namespace, data: MotionData, res: Identification
                 ) -> list[str]:
    """The latency from the poses alone, against the twist-based one.

    A base whose twist echoes the command, or is stamped differently from the pose,
    shows here: the poses are what the robot actually did.
    """
    from ..control.identification.identify import IdentificationError, identify_latency
    try:
        pose = identify_latency(data.commands, data.odometry, max_latency_s=args.max_latency,
                                max_tau_s=args.max_tau, source='pose', bootstrap=50,
                                command_timeout_s=args.command_timeout, seed=args.seed)
    except IdentificationError as exc:
        return [f'cross-check from the poses alone: not possible ({exc})']
    out = [f'cross-check from the poses alone: latency {pose.latency_s:.4f} s '
           f'{_fmt_interval(pose.latency_low_s, pose.latency_high_s)}']
    gap = max(pose.latency_low_s - res.latency_high_s, res.latency_low_s - pose.latency_high_s)
    if gap > 0.01:
        out.append(f'warning: the poses give a latency {gap:.3f} s outside the twist-based '
                   'interval: does the odometry twist echo the command, or carry another '
                   'stamp? Consider --source pose')
    return out


def register(subparsers: Subparsers) -> None:
    """Add ``identify`` to the CLI.

    Parameters
    ----------
    subparsers : argparse._SubParsersAction
        The CLI's sub-commands (``cli.build_parser``); ``identify`` is added to them.
    """
    p = subparsers.add_parser(
        'identify', help='command-to-motion latency and actuator lags from a bag',
        description='Estimate from a recorded run (cmd_vel as Twist or TwistStamped, '
        'nav_msgs/Odometry) the command-to-motion latency and the first-order time constants '
        'of v and w, with bootstrap intervals; write them for the latency-aware design.')
    p.add_argument('bag', help='rosbag2 bag directory (any robot; lockstep or real time)')
    p.add_argument('-o', '--output', help='identification YAML to write (e.g. latency.yaml; '
                   'never overwritten without --force)')
    p.add_argument('--force', action='store_true', help='overwrite --output if it exists')
    p.add_argument('--robot-file', metavar='ROBOT.yaml', help='robot file to write the '
                   'acceleration limits the recording shows binding into (its other keys and '
                   'comments kept; made from the shipped config/robot.yaml when absent)')
    p.add_argument('--cmd-topic', default='cmd_vel', help='velocity command topic (Twist or '
                   'TwistStamped; default cmd_vel, looked up as bag report does: in the '
                   'namespace holding most of the run topics, else at the root, else the one '
                   'topic of that type)')
    p.add_argument('--odom-topic', default='odom', help='odometry topic (nav_msgs/Odometry; '
                   'default odom, found as for --cmd-topic)')
    p.add_argument('--cmd-time', choices=['auto', 'receive', 'stamp'], default='auto',
                   help='time of a command: auto = header stamp of a TwistStamped, bag receive '
                   'time of a Twist')
    p.add_argument('--source', choices=['auto', 'twist', 'pose'], default='auto',
                   help='measure v, w from the odometry twist (auto: when not all zero) or '
                   'from differenced poses')
    p.add_argument('--truth', metavar='TOPIC', help='an external pose of the base in the bag '
                   '(PoseStamped or Odometry: motion capture, a simulator\'s true pose, e.g. '
                   'pose): identify the side slip the odometry does not see (side_slip_rates, '
                   'side_slip; docs: theory, "Side slip")')
    p.add_argument('--no-cross-check', dest='cross_check', action='store_false',
                   help='skip the check of a twist-based estimate against the poses alone')
    p.add_argument('--max-latency', type=float, default=1.0, help='latency search limit (s)')
    p.add_argument('--max-tau', type=float, default=1.0, help='time constant search limit (s)')
    p.add_argument('--command-timeout', type=float, default=None,
                   help="the base's cmd_vel watchdog (s): a command older than this counts "
                   'as zero (default: held until the next)')
    p.add_argument('--confidence', type=float, default=0.95, help='interval coverage')
    p.add_argument('--bootstrap', type=int, default=300, help='bootstrap replicates')
    p.add_argument('--seed', type=int, default=0, help='bootstrap seed')
    p.set_defaults(func=cmd_identify)
