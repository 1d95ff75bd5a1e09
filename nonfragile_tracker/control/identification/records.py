"""The identification's records: its inputs, its result and the file the design reads.

:class:`CommandSamples` and :class:`OdometrySamples` are what
:func:`~nonfragile_tracker.control.identification.identify.identify_latency` fits;
:class:`Identification` is its result, with two latency figures: ``latency_interval_s``,
the uncertainty of the mean latency, and ``latency_range_s``, the range it takes from
command to command (what the design certifies).  :func:`write_identification` and
:func:`read_identification` write and read (validating every field) the identification
file.  Nothing here imports ROS; numpy and PyYAML only.

See doc/tutorial.md, section "Identify the latency (``identify``)" (the file, field by
field), and doc/theory.md, section "Latency identification".
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from ...errors import InputError
from ..simulation.errors import LoopConfigError
from ..simulation.slip import check_slip_table
from ..validate import as_finite_float
from .errors import IdentificationError

__all__ = ['CommandSamples', 'OdometrySamples', 'Identification', 'write_identification',
           'read_identification', 'read_identification_text', 'with_source', 'FILE_KEY']

#: Top-level key of the identification file.
FILE_KEY = 'identification'


def _series(name: str, value: Any, n: int | None = None) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f'{name} must be a sequence of numbers, got {value!r}') from None
    if arr.ndim != 1:
        raise InputError(f'{name} must be one-dimensional, got shape {arr.shape}')
    if n is not None and arr.size != n:
        raise InputError(f'{name} has {arr.size} samples, expected {n} (one per time stamp)')
    return arr


@dataclass(frozen=True)
class CommandSamples:
    """Velocity commands: time ``t`` (s), ``v`` (m/s) and ``w`` (rad/s), held until the next.

    ``t`` is the receive time (geometry_msgs/Twist) or the header stamp
    (TwistStamped), on the same clock as the odometry stamps.
    """

    t: np.ndarray
    v: np.ndarray
    w: np.ndarray

    def __post_init__(self) -> None:
        t = _series('command t', self.t)
        object.__setattr__(self, 't', t)
        object.__setattr__(self, 'v', _series('command v', self.v, t.size))
        object.__setattr__(self, 'w', _series('command w', self.w, t.size))

    def __len__(self) -> int:
        return int(self.t.size)


@dataclass(frozen=True)
class OdometrySamples:
    """Odometry by measurement time ``t`` (s): pose ``x``, ``y`` (m), ``yaw`` (rad).

    ``v`` (m/s) and ``w`` (rad/s) are the body twist (``twist.linear.x``,
    ``twist.angular.z``) or ``None`` when the source has none.
    """

    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    yaw: np.ndarray
    v: np.ndarray | None = None
    w: np.ndarray | None = None

    def __post_init__(self) -> None:
        t = _series('odometry t', self.t)
        object.__setattr__(self, 't', t)
        for name in ('x', 'y', 'yaw', 'v', 'w'):
            val = getattr(self, name)
            if val is not None or name in ('x', 'y', 'yaw'):
                object.__setattr__(self, name, _series(f'odometry {name}', val, t.size))

    def __len__(self) -> int:
        return int(self.t.size)


@dataclass(frozen=True)
class Identification:
    """Identified latency and actuator lags with intervals (all times in s).

    The first block is what the identification file holds; the fields after
    ``source`` are diagnostics of :func:`.identify_latency` (NaN, ``''`` or 0 when
    read back from a file).
    """

    latency_s: float
    latency_low_s: float
    latency_high_s: float
    tau_v_s: float
    tau_v_low_s: float
    tau_v_high_s: float
    tau_w_s: float
    tau_w_low_s: float
    tau_w_high_s: float
    odom_rate_hz: float
    samples: int
    residual_rms_v: float
    residual_rms_w: float
    source: str = ''
    #: static gains g_v, g_w (measured / commanded at steady state)
    gain_v: float = math.nan
    gain_w: float = math.nan
    #: their intervals at ``confidence`` (block bootstrap; NaN: unknown)
    gain_v_low: float = math.nan
    gain_v_high: float = math.nan
    gain_w_low: float = math.nan
    gain_w_high: float = math.nan
    #: fraction of the measured variance explained by the model
    r2_v: float = math.nan
    r2_w: float = math.nan
    #: 'twist' or 'pose' (what each channel was measured from)
    source_v: str = ''
    source_w: str = ''
    #: the latency each channel alone would give (a consistency check)
    latency_v_s: float = math.nan
    latency_w_s: float = math.nan
    confidence: float = math.nan
    resolution_s: float = math.nan
    duration_s: float = math.nan
    commands: int = 0
    bootstrap: int = 0
    notes: tuple[str, ...] = field(default=())
    #: median period of the commands (s; NaN: unknown) - the sample-and-hold of the loop
    command_period_s: float = math.nan
    #: age of the newest odometry when a command is sent, 1st / 99th percentile (s; NaN:
    #: unknown), see :func:`.measurement_to_command_delay`
    command_age_low_s: float = math.nan
    command_age_high_s: float = math.nan
    #: the range the latency varies over from command to command (s; NaN: not measured,
    #: see :attr:`latency_range_s`) and what it was measured from
    latency_range_low_s: float = math.nan
    latency_range_high_s: float = math.nan
    latency_range_from: str = ''
    #: number of command steps whose latency was fitted one by one
    latency_events: int = 0
    #: acceleration limits of the base (m/s^2, rad/s^2; 0 = not seen to bind: unknown)
    max_linear_accel: float = 0.0
    max_angular_accel: float = 0.0
    #: fraction of the fitted time in which each limit binds (NaN: unknown)
    accel_binding_v: float = math.nan
    accel_binding_w: float = math.nan
    #: whether the commands were computed from the odometry (a tracker: True) or not (a
    #: joystick: False; their odometry age is then not recorded); None: unknown
    commands_follow_odometry: bool | None = None
    #: seconds excluded from the fit because the motion did not follow the commands
    excluded_s: float = 0.0
    #: the side-slip table to compensate (rad/s, s; ``identify --truth``, see
    #: :mod:`nonfragile_tracker.control.identification.slip`): empty when not identified or
    #: not significant
    side_slip_rates: tuple[float, ...] = ()
    side_slip: tuple[float, ...] = ()

    @property
    def latency_interval_s(self) -> tuple[float, float]:
        """(low, high) of the latency interval (s): the uncertainty of the mean latency."""
        return (self.latency_low_s, self.latency_high_s)

    @property
    def latency_range_s(self) -> tuple[float, float]:
        """(low, high) the latency varies over (s), containing the interval of the mean.

        The interval of the mean (:attr:`latency_interval_s`) when the range was not
        measured (an older file, or too few distinct command steps).
        """
        lo, hi = self.latency_range_low_s, self.latency_range_high_s
        if not (math.isfinite(lo) and math.isfinite(hi)):
            return self.latency_interval_s
        return (min(lo, self.latency_low_s), max(hi, self.latency_high_s))


# ---------------------------------------------------------------------------------------------
# File

def _num(x: float) -> str:
    return f'{float(x):.6g}' if abs(x) >= 1e-4 or x == 0 else f'{float(x):.6e}'


def write_identification(path: str | os.PathLike[str], result: Identification, *,
                         overwrite: bool = True) -> Path:
    """Write ``result`` as the identification file the latency-aware design reads.

    Parameters
    ----------
    path : path-like
        File to write (YAML; the format is in the module docstring).
    result : Identification
        What :func:`.identify_latency` returned (``source`` set by the caller, e.g.
        ``dataclasses.replace(result, source=str(bag))``).
    overwrite : bool
        If False, an existing file raises ``FileExistsError``.

    Returns
    -------
    pathlib.Path
        The path written.
    """
    p = Path(path)
    if not overwrite and p.exists():
        raise FileExistsError(f'{p} exists; pass --force to overwrite it')
    src = yaml.safe_dump(str(result.source), default_style=None).strip()
    if src.endswith('...'):
        src = src[:-3].strip()
    lines = [
        '# Command-to-motion latency and actuator lags identified by '
        '`nonfragile_tracker identify`',
        f'# (intervals: {100 * result.confidence:.0f} % block bootstrap; '
        f'tau_v/tau_w: first-order lag of v/w; residual_rms in m/s and rad/s)'
        if math.isfinite(result.confidence) else '# (intervals: as given)',
        f'{FILE_KEY}:',
        f'  source: {src}',
        f'  latency_s: {_num(result.latency_s)}',
        f'  latency_interval_s: [{_num(result.latency_low_s)}, {_num(result.latency_high_s)}]',
        f'  tau_v_s: {_num(result.tau_v_s)}',
        f'  tau_v_interval_s: [{_num(result.tau_v_low_s)}, {_num(result.tau_v_high_s)}]',
        f'  tau_w_s: {_num(result.tau_w_s)}',
        f'  tau_w_interval_s: [{_num(result.tau_w_low_s)}, {_num(result.tau_w_high_s)}]',
        f'  odom_rate_hz: {_num(result.odom_rate_hz)}',
        f'  samples: {int(result.samples)}',
        f'  residual_rms: {{v: {_num(result.residual_rms_v)}, w: {_num(result.residual_rms_w)}}}',
    ]
    if math.isfinite(result.command_period_s):
        lines.append(f'  command_period_s: {_num(result.command_period_s)}')
    if math.isfinite(result.command_age_low_s) and math.isfinite(result.command_age_high_s):
        lines.append(f'  command_age_s: [{_num(max(result.command_age_low_s, 0.0))}, '
                     f'{_num(max(result.command_age_high_s, 0.0))}]')
    if math.isfinite(result.latency_range_low_s) and math.isfinite(result.latency_range_high_s):
        lo, hi = result.latency_range_s
        lines.append(f'  latency_range_s: [{_num(lo)}, {_num(hi)}]   # the range the latency '
                     'varies over (latency_interval_s: the uncertainty of its mean)')
        if result.latency_range_from:
            lines.append(f'  latency_range_from: {_yaml_str(result.latency_range_from)}')
    lines.append(f'  max_linear_accel: {_num(result.max_linear_accel)}     # m/s^2, 0 = unknown')
    lines.append(f'  max_angular_accel: {_num(result.max_angular_accel)}    # rad/s^2, 0 = unknown')
    how = _accel_from(result)
    if how:
        lines.append(f'  accel_limits_from: {_yaml_str(how)}')
    if result.commands_follow_odometry is not None:
        lines.append('  commands_follow_odometry: '
                     f'{"true" if result.commands_follow_odometry else "false"}')
    if result.excluded_s > 0:
        lines.append(f'  excluded_s: {_num(result.excluded_s)}')
    if result.side_slip:
        lines.append('  side_slip_rates: [' + ', '.join(map(_num, result.side_slip_rates))
                     + ']   # rad/s')
        lines.append('  side_slip: [' + ', '.join(map(_num, result.side_slip))
                     + ']   # s: lateral speed -c(|w|) v w')
    text = '\n'.join(lines) + '\n'
    read_identification_text(text, str(p))            # never write what cannot be read back
    p.write_text(text)
    return p


_FIELDS = ('source', 'latency_s', 'latency_interval_s', 'tau_v_s', 'tau_v_interval_s',
           'tau_w_s', 'tau_w_interval_s', 'odom_rate_hz', 'samples', 'residual_rms')


_OPTIONAL = ('command_period_s', 'command_age_s', 'latency_range_s', 'latency_range_from',
             'max_linear_accel', 'max_angular_accel', 'accel_limits_from',
             'commands_follow_odometry', 'excluded_s', 'side_slip_rates', 'side_slip')


def _yaml_str(text: str) -> str:
    out = yaml.safe_dump(str(text), default_style=None, width=1000).strip()
    return out[:-3].strip() if out.endswith('...') else str(out)


def _accel_from(result: Identification) -> str:
    parts = []
    for name, a, frac in (('v', result.max_linear_accel, result.accel_binding_v),
                          ('w', result.max_angular_accel, result.accel_binding_w)):
        if a > 0 and math.isfinite(frac):
            parts.append(f'{name} binding {100 * frac:.0f} %')
    if not parts:
        return ''
    return 'rate-limited FOPDT fit (' + ', '.join(parts) + ' of the fitted time)'


def _text(where: str, key: str, value: Any) -> str:
    if not isinstance(value, str):
        raise IdentificationError(f'{where}: {FILE_KEY}.{key} must be a string, got '
                                  f'{value!r}')
    return value


def _number(where: str, key: str, value: Any, *, positive: bool = False) -> float:
    return as_finite_float(value, f'{where}: {FILE_KEY}.{key}', low=0.0,
                           low_inclusive=not positive, error=IdentificationError)


def _pair(where: str, key: str, value: Any, point: float) -> tuple[float, float]:
    if not isinstance(value, (list, tuple)) or len(value) != 2:
        raise IdentificationError(f'{where}: {FILE_KEY}.{key} must be a list [low, high] '
                                  f'of two numbers, got {value!r}')
    lo = _number(where, f'{key}[0]', value[0])
    hi = _number(where, f'{key}[1]', value[1])
    if not lo <= point <= hi:
        raise IdentificationError(f'{where}: {FILE_KEY}.{key} = [{lo:g}, {hi:g}] must '
                                  f'contain the estimate {point:g} (low <= value <= high)')
    return lo, hi


def read_identification_text(text: str, where: str = '<text>') -> Identification:
    """Parse and validate the text of an identification file (see :func:`read_identification`).

    Parameters
    ----------
    text : str
        The YAML text.
    where : str
        What the text is, for the messages (a file name).

    Returns
    -------
    Identification

    Raises
    ------
    IdentificationError
        The text is not YAML, has no ``identification`` mapping, or a field is missing or
        out of range, or unknown (the message names it).
    """
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise IdentificationError(f'{where} is not valid YAML: {exc}') from None
    if not isinstance(data, dict) or not isinstance(data.get(FILE_KEY), dict):
        raise IdentificationError(f'{where}: expected a mapping with the key {FILE_KEY!r} '
                                  '(written by `nonfragile_tracker identify BAG -o FILE`)')
    d = data[FILE_KEY]
    missing = [k for k in _FIELDS if k not in d]
    if missing:
        raise IdentificationError(f'{where}: {FILE_KEY} lacks the field(s) '
                                  f'{", ".join(missing)}')
    unknown = sorted(set(map(str, d)) - set(_FIELDS) - set(_OPTIONAL))
    if unknown:
        raise IdentificationError(f'{where}: {FILE_KEY} has unknown field(s) '
                                  f'{", ".join(unknown)}; known: '
                                  f'{", ".join(_FIELDS + _OPTIONAL)}')
    if not isinstance(d['source'], str):
        raise IdentificationError(f'{where}: {FILE_KEY}.source must be a string (the bag '
                                  f'path), got {d["source"]!r}')
    lat = _number(where, 'latency_s', d['latency_s'])
    lat_lo, lat_hi = _pair(where, 'latency_interval_s', d['latency_interval_s'], lat)
    tv = _number(where, 'tau_v_s', d['tau_v_s'])
    tv_lo, tv_hi = _pair(where, 'tau_v_interval_s', d['tau_v_interval_s'], tv)
    tw = _number(where, 'tau_w_s', d['tau_w_s'])
    tw_lo, tw_hi = _pair(where, 'tau_w_interval_s', d['tau_w_interval_s'], tw)
    rate = _number(where, 'odom_rate_hz', d['odom_rate_hz'], positive=True)
    n = d['samples']
    if isinstance(n, bool) or not isinstance(n, int) or n <= 0:
        raise IdentificationError(f'{where}: {FILE_KEY}.samples must be a positive '
                                  f'integer, got {n!r}')
    rr = d['residual_rms']
    if not isinstance(rr, dict) or set(rr) != {'v', 'w'}:
        raise IdentificationError(f'{where}: {FILE_KEY}.residual_rms must be a mapping '
                                  f'{{v: ..., w: ...}}, got {rr!r}')
    rv = _number(where, 'residual_rms.v', rr['v'])
    rw = _number(where, 'residual_rms.w', rr['w'])
    period = (_number(where, 'command_period_s', d['command_period_s'], positive=True)
              if 'command_period_s' in d else math.nan)
    age = (math.nan, math.nan)
    if 'command_age_s' in d:
        a = d['command_age_s']
        if not isinstance(a, (list, tuple)) or len(a) != 2:
            raise IdentificationError(f'{where}: {FILE_KEY}.command_age_s must be a list '
                                      f'[low, high] of two numbers, got {a!r}')
        age = _pair(where, 'command_age_s', a, _number(where, 'command_age_s[0]', a[0]))
    rng = (math.nan, math.nan)
    if 'latency_range_s' in d:
        rng = _pair(where, 'latency_range_s', d['latency_range_s'], lat)
    _text(where, 'accel_limits_from', d.get('accel_limits_from', ''))
    driven = d.get('commands_follow_odometry')
    if driven is not None and not isinstance(driven, bool):
        raise IdentificationError(f'{where}: {FILE_KEY}.commands_follow_odometry must be '
                                  f'true or false, got {driven!r}')
    try:
        slip = check_slip_table(d.get('side_slip_rates', ()), d.get('side_slip', ()))
    except LoopConfigError as exc:
        raise IdentificationError(f'{where}: {FILE_KEY}: {exc}') from None
    return Identification(lat, lat_lo, lat_hi, tv, tv_lo, tv_hi, tw, tw_lo, tw_hi, rate, n,
                          rv, rw, source=d['source'], command_period_s=period,
                          command_age_low_s=age[0], command_age_high_s=age[1],
                          latency_range_low_s=rng[0], latency_range_high_s=rng[1],
                          latency_range_from=_text(where, 'latency_range_from',
                                                   d.get('latency_range_from', '')),
                          max_linear_accel=_number(where, 'max_linear_accel',
                                                   d.get('max_linear_accel', 0.0)),
                          max_angular_accel=_number(where, 'max_angular_accel',
                                                    d.get('max_angular_accel', 0.0)),
                          commands_follow_odometry=driven,
                          excluded_s=_number(where, 'excluded_s', d.get('excluded_s', 0.0)),
                          side_slip_rates=slip[0], side_slip=slip[1])


def read_identification(path: str | os.PathLike[str]) -> Identification:
    """Read and validate an identification file written by :func:`write_identification`.

    Parameters
    ----------
    path : path-like
        The YAML file.

    Returns
    -------
    Identification
        The stored fields; diagnostics not stored in the file are NaN/empty.

    Raises
    ------
    IdentificationError
        Naming the field that is missing, unknown, of the wrong type, negative,
        non-finite, or an interval that does not contain its estimate.
    FileNotFoundError
        If ``path`` does not exist.
    """
    p = Path(path)
    if p.is_dir():
        raise IdentificationError(f'{p} is a directory; pass the identification YAML file '
                                  '(e.g. latency.yaml written by `identify -o`)')
    return read_identification_text(p.read_text(), str(p))


def with_source(result: Identification, source: str | os.PathLike[str]) -> Identification:
    """``result`` with its ``source`` (the bag path) set.

    Parameters
    ----------
    result : Identification
        An identification.
    source : str or os.PathLike
        Where its data came from (written to the file's ``source``).

    Returns
    -------
    Identification
    """
    return replace(result, source=str(source))
