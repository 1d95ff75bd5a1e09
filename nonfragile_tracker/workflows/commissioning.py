"""The bring-up's ROS-free steps: robot settings, identify, design, write the files and report.

``nonfragile_tracker bringup`` (the node :mod:`nonfragile_tracker.nodes.bringup` drives
the robot) is the four-command path in one: record (the designed excitation,
:mod:`nonfragile_tracker.control.identification.excitation`) -> identify
(:func:`identify_recording`: refuses with the cause and what to change when the data is
not informative) -> design (:func:`design_gain`: ``latency-design`` from the
identification; refuses naming the latency when no gain within the bound certifies it)
-> trial -> files (:func:`write_robot_file`, the gain file) and a report
(:func:`write_report`: markdown and PNGs).  The heavy steps run in a child process of the
node (:func:`analyse` and :func:`report`, through :func:`run_child`) so that the node keeps
answering a stop signal within 0.1 s while the SDPs run.

See doc/tutorial.md, section "One command (bringup)".
"""
from __future__ import annotations

import json
import math
import os
import traceback
from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from ..errors import InputError
from ..interface.robot import (GAIN_FILE, IDENTIFICATION_FILE, OUTCOME_FILE, REPORT_FILE,
                               ROBOT_FILE, RobotConfig, identified_limits, update_robot_file)

if TYPE_CHECKING:
    from ..bag.motion import MotionData
    from ..control.identification.identify import CommandSamples, Identification, OdometrySamples
    from ..control.synthesis.latency_design import LatencyDesign, LatencyPlan

__all__ = ['BringupRefusal', 'bringup_limits', 'identify_recording', 'identify_samples',
           'side_slip_from_truth',
           'design_gain',
           'write_robot_file', 'write_report', 'analyse', 'report', 'run_child',
           'IDENTIFICATION_FILE', 'GAIN_FILE', 'ROBOT_FILE', 'REPORT_FILE',
           'OUTCOME_FILE']


class BringupRefusal(InputError):
    """The bring-up stops here: the cause and what to change (exit code 2, no gain written)."""


def bringup_limits(robot: RobotConfig, max_speed: float | None = None,
                   max_turn_rate: float | None = None) -> tuple[float, float]:
    """The bring-up's speed limits: the user's (default 0.3 m/s, 1 rad/s) or the robot's if lower.

    Parameters
    ----------
    robot : RobotConfig
        The robot file's settings.
    max_speed, max_turn_rate : float, optional
        The user's limits (m/s, rad/s).

    Returns
    -------
    (float, float)
        ``(|v| limit, |w| limit)``.
    """
    from ..control.identification.excitation import DEFAULT_SPEED, DEFAULT_TURN_RATE
    v = DEFAULT_SPEED if max_speed is None else float(max_speed)
    w = DEFAULT_TURN_RATE if max_turn_rate is None else float(max_turn_rate)
    return min(v, robot.max_linear_speed), min(w, robot.max_angular_speed)


def identify_recording(bag: str | os.PathLike[str], *, cmd_topic: str = 'cmd_vel',
                       odom_topic: str = 'odom', odom_period: float = 0.02,
                       accel_segment: bool = True) -> Identification:
    """Identify latency, lags and limits from the excitation's bag, or refuse with the cause.

    Parameters
    ----------
    bag : path-like
        The excitation's bag.
    cmd_topic, odom_topic : str
        Topic names in the bag.
    odom_period : float
        The odometry period (s): a latency interval wider than two of them is not
        informative.
    accel_segment : bool
        Whether the excitation had its acceleration segment (said in a refusal).

    Returns
    -------
    Identification

    Raises
    ------
    BringupRefusal
        When the data is not informative, with the cause and what to change.
    """
    return _read_and_identify(bag, cmd_topic, odom_topic, odom_period, accel_segment)[1]


def _read_and_identify(bag: str | os.PathLike[str], cmd_topic: str, odom_topic: str,
                       odom_period: float, accel_segment: bool
                       ) -> tuple[MotionData, Identification]:
    """The bag's motion (read once) and :func:`identify_recording`'s identification of it."""
    from ..bag.motion import read_motion
    from ..control.identification.identify import with_source
    data = read_motion(bag, cmd_topic=cmd_topic, odom_topic=odom_topic)
    res = identify_samples(data.commands, data.odometry, odom_period=odom_period,
                           accel_segment=accel_segment)
    return data, with_source(res, bag)


def identify_samples(commands: CommandSamples, odometry: OdometrySamples, *,
                     odom_period: float = 0.02, accel_segment: bool = True
                     ) -> Identification:
    """:func:`identify_recording` on commands and odometry already read.

    Parameters
    ----------
    commands : CommandSamples
        The commands with their times.
    odometry : OdometrySamples
        The odometry by measurement time.
    odom_period : float
        The odometry period (s).
    accel_segment : bool
        Whether the excitation had its acceleration segment.

    Returns
    -------
    Identification

    Raises
    ------
    BringupRefusal
        When the data is not informative, with the cause and what to change.
    """
    from ..control.identification.errors import (InsufficientExcitationError,
                                                NotEnoughDataError, PoorFitError)
    from ..control.identification.identify import identify_latency
    try:
        res = identify_latency(commands, odometry, bootstrap=200)
    except NotEnoughDataError as exc:
        raise BringupRefusal(f'not enough data to identify the base: {exc}. What to change: '
                             'check that the odometry topic is the robot\'s and publishes '
                             'while it drives, and that the run was not cut short') from None
    except InsufficientExcitationError as exc:
        raise BringupRefusal(f'the recording does not excite the base: {exc}. What to change: '
                             'the base hardly moved or hardly turned - check that it is '
                             'powered and not e-stopped, and give a larger box (--box) or '
                             'higher limits (--max-speed, --max-turn-rate)') from None
    except PoorFitError as exc:
        raise BringupRefusal(f'the base\'s response is not a latency and a lag: {exc}. What '
                             'to change: check that cmd_vel reaches this base (topic, '
                             'Twist/TwistStamped) and that the odometry is its own') from None
    lo, hi = res.latency_interval_s
    if hi - lo > 2.0 * odom_period + 0.01:
        raise BringupRefusal(
            f'the latency is not pinned down: {res.latency_s:.4f} s with the 95 % interval '
            f'[{lo:.4f}, {hi:.4f}] s, wider than two odometry periods ({odom_period:.3f} s): '
            'the base\'s latency varies during the run, or the steps are too small to time. '
            'What to change: if the latency varies (a busy controller, a lossy link, a '
            'bridge that batches commands), reduce the variation - no gain is designed for a '
            'latency that is not known; otherwise give a larger box (--box) or higher limits '
            '(--max-speed, --max-turn-rate) for larger steps')
    unseen = [name for name, value in (('linear', res.max_linear_accel),
                                       ('angular', res.max_angular_accel)) if not value > 0]
    if unseen and not accel_segment:
        res = replace(res, notes=tuple(res.notes) + (
            f'{" and ".join(unseen)} acceleration limit not seen (0 = unknown): the '
            'excitation had no acceleration segment (bringup --no-accel-segment)',))
    elif unseen:
        res = replace(res, notes=tuple(res.notes) + tuple(
            f'{name} acceleration limit not seen (0 = unknown): it did not bind in the '
            'acceleration segment\'s steps, so the base follows them (or its lag hides a '
            'limit that binds for less than an odometry period); the robot file keeps 0'
            for name in unseen))
    return res


@dataclass(frozen=True)
class DesignOutcome:
    """The designed gain and what it was designed from."""

    plan: LatencyPlan
    design: LatencyDesign
    gain_file: Path
    summary: str


def side_slip_from_truth(bag: str | os.PathLike[str], ident: Identification, truth_topic: str,
                         *, odom_topic: str = 'odom', odometry: OdometrySamples | None = None,
                         strict: bool = False) -> tuple[Identification, str]:
    """The identification with the side-slip table from an external pose, when it matters.

    Parameters
    ----------
    bag : path-like
        The recording (odometry and ``truth_topic``).
    ident : Identification
        What :func:`identify_recording` found.
    truth_topic : str
        The external pose's topic; '' = none (``ident`` unchanged).
    odom_topic : str
        The odometry's topic (read unless ``odometry`` is given).
    odometry : OdometrySamples, optional
        The bag's odometry, already read.
    strict : bool
        Raise when ``truth_topic`` cannot be read (``identify --truth``); else say so in the
        line (the bring-up: its analysis goes on without a side slip).

    Returns
    -------
    (Identification, str)
        ``ident`` with ``side_slip_rates`` / ``side_slip`` set when the table is significant
        (:class:`~nonfragile_tracker.control.identification.slip.SideSlip`), and one line
        saying what was found (or why nothing was: no topic, too little turning).

    Raises
    ------
    MissingTopicsError
        With ``strict``, if ``truth_topic`` is absent, of another type or empty.
    """
    if not truth_topic:
        return ident, 'side slip: no external pose (truth_topic): not identified'
    from ..bag.motion import read_motion, read_poses
    from ..control.identification.slip import identify_side_slip
    try:
        truth = read_poses(bag, truth_topic)
    except InputError as exc:
        if strict:
            raise
        return ident, f'side slip from {truth_topic}: not identified ({exc})'
    try:
        if odometry is None:
            odometry = read_motion(bag, odom_topic=odom_topic).odometry
        slip = identify_side_slip(odometry, truth)
    except InputError as exc:
        return ident, f'side slip from {truth_topic}: not identified ({exc})'
    line = f'side slip from {truth_topic}: {slip.summary()}'
    if not slip.significant:
        return ident, line
    return replace(ident, side_slip_rates=slip.rates, side_slip=slip.coefficients), line


def design_gain(ident: Identification, problem: str | os.PathLike[str],
                gain_file: str | os.PathLike[str], *, extra: Mapping[str, Any] | None = None
                ) -> DesignOutcome:
    """``latency-design PROBLEM --identification``: the gain file, or a refusal naming the latency.

    Parameters
    ----------
    ident : Identification
        From :func:`identify_recording`.
    problem : path-like
        The problem file (``config/paper_problem.yaml``: its gain bound and perturbation).
    gain_file : path-like
        Where to write the gain (replaced if it exists).
    extra : mapping, optional
        More tracker parameters for the gain file (the robot's limits).

    Returns
    -------
    DesignOutcome

    Raises
    ------
    BringupRefusal
        When no gain within the bound certifies the identified latency.
    """
    from ..control.identification.monitor import certificate_from_design
    from ..control.simulation.gains import write_gain_file
    from ..control.synthesis.errors import InfeasibleError
    from ..control.synthesis.latency_design import (design_for_latency, gain_verdict,
                                                    plan_from_identification)
    from ..control.synthesis.problem import load_problem
    prob = load_problem(Path(problem))
    plan = plan_from_identification(ident)
    r0, r1 = ident.latency_range_s
    bound = prob.options.get('gain_bound')
    try:
        res = design_for_latency(prob, plan.h_min, plan.h_max, lag=plan.lag)
    except InfeasibleError:
        raise BringupRefusal(
            f'the identified latency {ident.latency_s:.4f} s (varying over [{r0:.4f}, '
            f'{r1:.4f}] s; residual delay after the predictor [{plan.h_min:.4f}, '
            f'{plan.h_max:.4f}] s with the lag {plan.lag:.4f} s) is beyond what any gain '
            f'with ||K||_2 <= {bound} certifies: no gain was written. What to change: '
            'reduce the latency and its variation on the robot (command transport, '
            'controller rate, odometry stamping), or allow a larger gain bound in the '
            'problem file') from None
    meta = {**res.metadata(), **plan.metadata()}
    params: dict[str, Any] = {**plan.tracker_parameters(), **plan.actuator_parameters(),
                              **plan.gain_parameters(), **plan.slip_parameters()}
    verdict = gain_verdict(plan, prob, res.K)
    if verdict is not None:
        meta.update(verdict[1])
    cert = certificate_from_design(meta, hold=0.0)
    if cert is not None:
        params.update(cert.parameters())
        if not params.get('certified_adapt_range'):
            params.pop('certified_adapt_range', None)
    for k, v in (extra or {}).items():
        params.setdefault(k, v)
    summary = plan.describe() + '\n' + res.summary() + (
        '' if verdict is None else '\n' + verdict[0])
    write_gain_file(gain_file, res.K, comment='Generated by `nonfragile_tracker bringup`\n'
                    + summary, overwrite=True, extra=params, design=meta)
    return DesignOutcome(plan=plan, design=res, gain_file=Path(gain_file), summary=summary)


def write_robot_file(path: str | os.PathLike[str], robot: RobotConfig,
                     ident: Identification) -> Path:
    """The robot file with the identified limits: the user's file, unknown limits filled in.

    A copy of the robot file the bring-up started from (:attr:`.RobotConfig.source`; the
    shipped one with ``robot``'s values when it had none), comments kept, where an
    acceleration limit the identification found replaces an unknown one (0) and a known
    one is kept
    (:func:`nonfragile_tracker.interface.robot.update_robot_file` with ``only_unknown``).  The
    identified latency and lags go to the identification and gain files.

    Parameters
    ----------
    path : path-like
        Where to write it (replaced).
    robot : RobotConfig
        The robot file's settings the bring-up started from.
    ident : Identification
        The identification.

    Returns
    -------
    pathlib.Path
    """
    out = Path(path)
    out.unlink(missing_ok=True)
    if not robot.source:            # settings made in code: they are the file's values
        update_robot_file(out, robot.parameters(), note='the bring-up\'s robot settings')
    update_robot_file(out, identified_limits(ident),
                      note=f'bringup, identified from {ident.source}',
                      template=robot.source or None, only_unknown=True)
    return out


def _model_response(t_cmd: np.ndarray, u: np.ndarray, t: np.ndarray, latency: float,
                    tau: float, gain: float) -> np.ndarray:
    """First-order lag with dead time driven by the held commands, sampled at ``t``."""
    h = 0.002
    grid = np.arange(t[0], t[-1] + h, h)
    idx = np.searchsorted(t_cmd, grid - latency, side='right') - 1
    held = np.where(idx >= 0, u[np.clip(idx, 0, None)], 0.0) * gain
    y = np.zeros_like(grid)
    k = math.exp(-h / tau) if tau > 0 else 0.0
    for i in range(1, grid.size):
        y[i] = k * y[i - 1] + (1.0 - k) * held[i - 1]
    return cast(np.ndarray, np.interp(t, grid, y))


def plot_identification(bag: str | os.PathLike[str], ident: Identification,
                        out: str | os.PathLike[str], *, cmd_topic: str = 'cmd_vel',
                        odom_topic: str = 'odom') -> Path:
    """PNG of the identified responses against the data: v and w, command, measured, model.

    Parameters
    ----------
    bag : path-like
        The excitation's bag.
    ident : Identification
        The identification.
    out : path-like
        The PNG to write.
    cmd_topic, odom_topic : str
        Topic names in the bag.

    Returns
    -------
    pathlib.Path
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from ..bag.motion import read_motion
    data = read_motion(bag, cmd_topic=cmd_topic, odom_topic=odom_topic)
    c, o = data.commands, data.odometry
    t0 = float(c.t[0])
    fig = Figure(figsize=(10, 6))
    FigureCanvasAgg(fig)
    for i, (name, u, meas, tau, g, unit) in enumerate((
            ('v', c.v, o.v, ident.tau_v_s, ident.gain_v, 'm/s'),
            ('w', c.w, o.w, ident.tau_w_s, ident.gain_w, 'rad/s'))):
        ax = fig.add_subplot(2, 1, i + 1)
        ax.step(c.t - t0, u, where='post', lw=0.8, label=f'command {name}')
        if meas is not None:
            ax.plot(o.t - t0, meas, '.', ms=2, label='odometry')
            model = _model_response(c.t, u, o.t, ident.latency_s, tau, g)
            ax.plot(o.t - t0, model, lw=1.0, label=f'model: L = {ident.latency_s:.3f} s, '
                    f'tau = {tau:.3f} s')
        ax.set_ylabel(f'{name} ({unit})')
        ax.legend(loc='upper right', fontsize=7)
        ax.grid(True, alpha=0.3)
    fig.axes[-1].set_xlabel('time (s)')
    fig.suptitle('bring-up: identified responses against the data')
    path = Path(out)
    fig.savefig(path, dpi=90)
    return path


def analyse(bag: str | os.PathLike[str], run_dir: str | os.PathLike[str],
            settings: Mapping[str, Any]) -> dict[str, Any]:
    """Identify and design from the excitation's bag; write the files; the outcome as a dict.

    Parameters
    ----------
    bag : path-like
        The excitation's bag.
    run_dir : path-like
        The run folder (the identification, gain and robot files go there).
    settings : mapping
        ``robot`` (:class:`~nonfragile_tracker.interface.robot.RobotConfig` as a dict),
        ``problem`` (path), ``odom_period`` (s), ``accel_segment`` (bool).

    Returns
    -------
    dict
        ``ok``; with ``ok`` the identification's figures and file names; without it
        ``phase`` (identify or design) and ``refusal`` (the cause and what to change).
    """
    from ..control.identification.identify import write_identification
    run = Path(run_dir)
    robot = RobotConfig(**settings['robot'])
    try:
        data, ident = _read_and_identify(bag, robot.cmd_vel_topic, robot.odom_topic,
                                         float(settings['odom_period']),
                                         bool(settings['accel_segment']))
    except InputError as exc:
        return {'ok': False, 'phase': 'identify', 'refusal': str(exc)}
    ident, slip_line = side_slip_from_truth(bag, ident, str(settings.get('truth_topic') or ''),
                                            odometry=data.odometry)
    write_identification(run / IDENTIFICATION_FILE, ident, overwrite=True)
    ident_fig = plot_identification(bag, ident, run / 'identification.png',
                                     cmd_topic=robot.cmd_vel_topic, odom_topic=robot.odom_topic)
    limits = {'max_linear_speed': robot.max_linear_speed,
              'max_angular_speed': robot.max_angular_speed}
    for key in ('max_linear_accel', 'max_angular_accel'):
        if getattr(robot, key) > 0:
            limits[key] = getattr(robot, key)
    try:
        out = design_gain(ident, settings['problem'], run / GAIN_FILE, extra=limits)
    except InputError as exc:
        return {'ok': False, 'phase': 'design', 'refusal': str(exc),
                'latency_s': ident.latency_s}
    write_robot_file(run / ROBOT_FILE, robot, ident)
    d = out.design
    return {'ok': True, 'latency_s': ident.latency_s,
            'latency_interval_s': list(ident.latency_interval_s),
            'latency_range_s': list(ident.latency_range_s),
            'tau_v_s': ident.tau_v_s, 'tau_w_s': ident.tau_w_s,
            'tau_v_interval_s': [ident.tau_v_low_s, ident.tau_v_high_s],
            'tau_w_interval_s': [ident.tau_w_low_s, ident.tau_w_high_s],
            'max_linear_accel': ident.max_linear_accel,
            'max_angular_accel': ident.max_angular_accel,
            'odom_rate_hz': ident.odom_rate_hz, 'notes': list(ident.notes),
            'gain_norm': d.gain_norm, 'decay_rate': d.decay_rate,
            'residual': [out.plan.h_min, out.plan.h_max], 'lag': out.plan.lag,
            'certified_h_max': d.lag_certified_h_max if d.lag_certified_h_max is not None
            else d.certified_h_max,
            'predict_latency': out.plan.predict_latency, 'summary': out.summary,
            'identification_file': str(run / IDENTIFICATION_FILE),
            'gain_file': str(out.gain_file), 'robot_file': str(run / ROBOT_FILE),
            'identification_png': str(ident_fig),
            'side_slip': slip_line, 'side_slip_rates': list(ident.side_slip_rates),
            'side_slip_coefficients': list(ident.side_slip)}


def run_child(task_file: str) -> int:
    """Child-process entry of the bring-up node: :func:`analyse` or :func:`report` of a task.

    The child ignores SIGINT (a terminal's Ctrl-C reaches the whole process group; the node
    stops and kills the child) and runs at a lower priority than the node's control loop.

    Parameters
    ----------
    task_file : str
        JSON: ``task`` (``analyse``: ``bag``, ``run_dir``, ``settings``, ``excitation``;
        ``report``: ``run_dir``, ``outcome``, ``trial``, ``excitation``).

    Returns
    -------
    int
        0; the outcome (or the error) is in the run folder's files.
    """
    import signal
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        os.nice(10)
    except OSError:
        pass
    spec = json.loads(Path(task_file).read_text())
    if spec['task'] == 'analyse':
        _analyse_to_file(spec['bag'], spec['run_dir'], spec['settings'],
                         spec.get('excitation', {}))
    else:
        report(spec['run_dir'], spec['outcome'], spec['trial'], spec['excitation'])
    return 0


def _analyse_to_file(bag: str, run_dir: str, settings: dict[str, Any],
                     excitation: Mapping[str, Any]) -> None:
    """:func:`analyse`'s outcome (or error) into ``analysis.json``; a refusal's report too."""
    path = Path(run_dir) / OUTCOME_FILE
    try:
        outcome = analyse(bag, run_dir, settings)
    except Exception as exc:  # noqa: BLE001 - reported to the parent, which stops cleanly
        outcome = {'ok': False, 'phase': 'analysis', 'refusal': f'{type(exc).__name__}: {exc}',
                   'traceback': traceback.format_exc()}
    if not outcome.get('ok'):
        write_report(run_dir, outcome, None, excitation)
    tmp = path.with_suffix('.tmp')
    tmp.write_text(json.dumps(outcome, indent=2, default=float))
    tmp.replace(path)


def _limit(value: float, unit: str) -> str:
    """An identified limit for the report: its value, or that it was not seen."""
    return f'{value:.3g} {unit}' if value > 0 else f'not seen (0 = unknown) {unit}'


def write_report(run_dir: str | os.PathLike[str], outcome: Mapping[str, Any],
                 trial: Mapping[str, Any] | None, excitation: Mapping[str, Any]) -> Path:
    """The bring-up's report: markdown with the figures, next to its PNGs.

    Parameters
    ----------
    run_dir : path-like
        The run folder.
    outcome : mapping
        :func:`analyse`'s result.
    trial : mapping or None
        The trial's figures (``rms_error``, ``rms_cross_track``, ``max_error``,
        ``certificate`` ...; None if there was none).
    excitation : mapping
        The excitation's figures (``duration``, ``max_distance`` ...).

    Returns
    -------
    pathlib.Path
        The markdown file.
    """
    run = Path(run_dir)
    lines = ['# Bring-up report', '',
             f'Run folder `{run}`.', '', '## Excitation', '']
    lines += [f'- {k.replace("_", " ")}: {v:.4g}' if isinstance(v, float) else
              f'- {k.replace("_", " ")}: {v}' for k, v in excitation.items()
              if not k.endswith('png')]
    if excitation.get('path_png'):
        lines += ['', f'![the excitation\'s path](excitation_report/'
                  f'{Path(str(excitation["path_png"])).name})']
    lines += ['', '## Identification', '']
    if outcome.get('ok') or 'latency_s' in outcome:
        lines.append(f'- latency {outcome["latency_s"]:.4f} s')
    if outcome.get('ok'):
        lo, hi = outcome['latency_interval_s']
        lines += [f'- latency 95 % interval [{lo:.4f}, {hi:.4f}] s, range '
                  f'[{outcome["latency_range_s"][0]:.4f}, {outcome["latency_range_s"][1]:.4f}] s',
                  f'- lag of v {outcome["tau_v_s"]:.4f} s, lag of w {outcome["tau_w_s"]:.4f} s',
                  f'- acceleration limits {_limit(outcome["max_linear_accel"], "m/s^2")}, '
                  f'{_limit(outcome["max_angular_accel"], "rad/s^2")}',
                  *[f'- note: {n}' for n in outcome.get('notes', [])],
                  *([f'- {outcome["side_slip"]}'] if outcome.get('side_slip') else []),
                  '', '![identified responses](identification.png)', '',
                  '## Design (the certified interval)', '', '```text', outcome['summary'],
                  '```', '']
    else:
        lines += ['', f'**Refused ({outcome.get("phase")}):** {outcome.get("refusal")}', '']
    if trial is not None:
        lines += ['## Trial with the designed gain', '']
        lines += [f'- {k.replace("_", " ")}: {v:.4g}' if isinstance(v, float) else
                  f'- {k.replace("_", " ")}: {v}' for k, v in trial.items()
                  if not k.endswith('png')]
        if trial.get('errors_png'):
            lines += ['', f'![trial errors](trial_report/{Path(str(trial["errors_png"])).name})']
        lines.append('')
    path = run / REPORT_FILE
    path.write_text('\n'.join(lines) + '\n')
    return path


def report(run_dir: str | os.PathLike[str], outcome: Mapping[str, Any],
           trial: Mapping[str, Any] | None, excitation: Mapping[str, Any]) -> str:
    """The figures of both bags (``bag report``), the trial's certificate check, the report.

    Parameters
    ----------
    run_dir : path-like
        The run folder (``bag``, ``trial_bag``).
    outcome : mapping
        :func:`analyse`'s result.
    trial : mapping or None
        The trial's figures from the node (None: no trial).
    excitation : mapping
        The excitation's figures from the node.

    Returns
    -------
    str
        The certificate monitor's status over the trial (also in ``report.json``).
    """
    from ..bag.report import bag_report, certificate_check, certificate_source
    run = Path(run_dir)
    tr = dict(trial) if trial is not None else None
    ex = dict(excitation)
    status = 'no trial'
    try:
        rep = bag_report(run / 'bag', run / 'excitation_report', overwrite=True)
        if 'xy' in rep.plots:
            ex['path_png'] = str(rep.plots['xy'])
    except Exception as exc:  # noqa: BLE001 - the report says what failed
        ex['report'] = f'not written ({type(exc).__name__}: {exc})'
    bag = run / 'trial_bag'
    if tr is not None and bag.exists():
        try:
            src = certificate_source(bag, outcome.get('gain_file'))
            if src is not None:
                cert, params, source = src
                chk = certificate_check(bag, cert, params, source=source)
                status = (f'{100 * chk.inside:.0f} % of windows inside the certified interval, '
                          f'{100 * chk.outside:.0f} % outside, {100 * chk.unknown:.0f} % unknown; '
                          f'last: {chk.last_message}')
                tr['certificate'] = status
            rep = bag_report(bag, run / 'trial_report', overwrite=True)
            errors = rep.plots.get('errors')
            if errors is not None:
                tr['errors_png'] = str(errors)
        except Exception as exc:  # noqa: BLE001 - the report says what failed
            status = f'not checked ({type(exc).__name__}: {exc})'
            tr['certificate'] = status
    write_report(run, outcome, tr, ex)
    (run / 'report.json').write_text(json.dumps({'certificate': status, 'trial': tr},
                                                default=float))
    return status
