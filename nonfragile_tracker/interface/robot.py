"""The robot file: one commented file per base with what the tracker needs to know about it.

A ROS 2 parameter file with one section, the tracker's (the shipped, commented example is
``config/robot.yaml``): topics, frames, Twist or TwistStamped, speed and acceleration limits,
minimum turning radius, input timeout; every key (:data:`KEYS`) is a tracker parameter, so
it also works as ``--params-file``.  :func:`load_robot_file` reads and checks it into a
:class:`RobotConfig` (refusals: :class:`RobotFileError`, naming the file, the key and what
to write); :func:`update_robot_file` writes identified values into it keeping its comments
(:func:`identified_limits`).  No ROS import here.

See doc/ros-interface.md, section "The robot file" (the format, the checks, how the
bring-up writes it, how to add a key).
"""
from __future__ import annotations

import io
import math
import os
import re
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from . import topics
from ..errors import InputError
from ..files import node_key, read_yaml
from .resources import config_dir

if TYPE_CHECKING:
    from ..control.identification.identify import Identification

__all__ = ['RobotFileError', 'RobotKey', 'KEYS', 'NODE', 'ROBOT_FILE', 'IDENTIFICATION_FILE',
           'GAIN_FILE', 'REPORT_FILE', 'OUTCOME_FILE', 'RobotConfig',
           'robot_file', 'check_topic_name', 'check_frame_name', 'parse_robot_parameters',
           'load_robot_file', 'update_robot_file', 'identified_limits', 'Change']

#: The node whose section a robot file holds.
NODE = 'tracker'
#: The shipped robot file in ``config/``.
ROBOT_FILE = 'robot.yaml'
#: The other files a bring-up writes into its run folder (beside :data:`ROBOT_FILE`): the
#: identification, the gain, the report, and the analysis outcome the bring-up node reads.
IDENTIFICATION_FILE = 'latency.yaml'
GAIN_FILE = 'gains.yaml'
REPORT_FILE = 'report.md'
OUTCOME_FILE = 'analysis.json'


class RobotFileError(InputError):
    """A robot file that cannot be used: unreadable, wrong layout, unknown key, bad value."""


@dataclass(frozen=True)
class RobotKey:
    """One key of a robot file: its type, the tracker's default, range and meaning.

    ``low``/``high`` bound a number (the tracker's range);
    ``zero`` says what 0 means when 0 is allowed and special (``'unknown'``, ``'none'``).
    """

    name: str
    kind: type
    default: Any
    meaning: str
    low: float | None = None
    high: float | None = None
    zero: str = ''


#: The keys of a robot file in the order of the shipped file; defaults and ranges are the
#: tracker's (``nodes/tracker.py``), the topic and frame names those of :mod:`.topics`.
KEYS: tuple[RobotKey, ...] = (
    RobotKey('odom_topic', str, topics.ODOM, 'odometry topic (nav_msgs/Odometry)'),
    RobotKey('cmd_vel_topic', str, topics.CMD_VEL, 'velocity command topic'),
    RobotKey('enable_stamped_cmd_vel', bool, False,
             'command type: true = geometry_msgs/TwistStamped, false = Twist'),
    RobotKey('odom_frame', str, topics.ODOM_FRAME, 'frame of odometry and trajectories'),
    RobotKey('base_frame', str, topics.BASE_FRAME, 'robot body frame'),
    RobotKey('max_linear_speed', float, 1.0, '|v| limit (m/s)', 1e-9, 1e3),
    RobotKey('max_angular_speed', float, 2.0, '|w| limit (rad/s)', 1e-9, 1e3),
    RobotKey('max_linear_accel', float, 0.0, '|dv/dt| limit (m/s^2)', 0.0, 1e3,
             zero='unknown'),
    RobotKey('max_angular_accel', float, 0.0, '|dw/dt| limit (rad/s^2)', 0.0, 1e3,
             zero='unknown'),
    RobotKey('min_turning_radius', float, 0.0, 'tightest turn the base can drive (m)', 0.0,
             1e3, zero='none'),
    RobotKey('input_timeout', float, 0.5, 'stop when an input is older than this (s)', 1e-6,
             1e6),
)
_BY_NAME = {k.name: k for k in KEYS}
#: A ROS 2 topic name: tokens of letters, digits and underscores (not starting with a
#: digit) separated by single slashes, optionally absolute (``/``) or private (``~/``).
_TOPIC = re.compile(r'^(~/|/)?[A-Za-z_][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*$')
#: A tf2 frame id: no leading slash (tf2 refuses it), no spaces.
_FRAME = re.compile(r'^[A-Za-z0-9_][A-Za-z0-9_./-]*$')


@dataclass(frozen=True)
class RobotConfig:
    """A validated robot file (see the module docstring for each field's meaning)."""

    odom_topic: str = topics.ODOM
    cmd_vel_topic: str = topics.CMD_VEL
    enable_stamped_cmd_vel: bool = False
    odom_frame: str = topics.ODOM_FRAME
    base_frame: str = topics.BASE_FRAME
    max_linear_speed: float = 1.0
    max_angular_speed: float = 2.0
    max_linear_accel: float = 0.0
    max_angular_accel: float = 0.0
    min_turning_radius: float = 0.0
    input_timeout: float = 0.5
    #: the file it was read from ('' when built in code)
    source: str = ''

    def parameters(self) -> dict[str, Any]:
        """The tracker parameters of this robot, by name (every key of :data:`KEYS`).

        Returns
        -------
        dict
            ``{name: value}``, doubles as ``float``: what ``robot.launch.py`` passes to the
            tracker node.
        """
        values = asdict(self)
        return {k.name: values[k.name] for k in KEYS}


def robot_file() -> Path:
    """The shipped robot file, ``config/robot.yaml`` (source tree or installed share).

    Returns
    -------
    pathlib.Path
    """
    return config_dir() / ROBOT_FILE


def check_topic_name(name: Any, key: str, where: str = '') -> str:
    """``name`` if it is a valid ROS 2 topic name, else :class:`RobotFileError`.

    Parameters
    ----------
    name : object
        The value to check.
    key : str
        The parameter it is the value of (for the message).
    where : str, optional
        The file (for the message).

    Returns
    -------
    str
    """
    if not isinstance(name, str) or not _TOPIC.match(name):
        raise RobotFileError(f'{where}{key} is {name!r}: a ROS 2 topic name is needed (letters, '
                             'digits, _ and single /, not starting with a digit), e.g. odom '
                             'or /diff_drive_controller/odom')
    return name


def check_frame_name(name: Any, key: str, where: str = '') -> str:
    """``name`` if it is a valid tf2 frame id (no leading ``/``), else :class:`RobotFileError`.

    Parameters
    ----------
    name : object
        The value to check.
    key : str
        The parameter it is the value of (for the message).
    where : str, optional
        The file (for the message).

    Returns
    -------
    str
    """
    if not isinstance(name, str) or not _FRAME.match(name):
        raise RobotFileError(f'{where}{key} is {name!r}: a tf2 frame id is needed (no leading '
                             '/ and no spaces), e.g. odom or base_link')
    return name


def _value(key: RobotKey, value: Any, where: str) -> Any:
    """One value checked against its key (type, range), as the tracker will take it."""
    if key.kind is bool:
        if not isinstance(value, bool):
            raise RobotFileError(f'{where}{key.name} is {value!r}: write true or false '
                                 f'({key.meaning})')
        return value
    if key.kind is str:
        if key.name.endswith('_topic'):
            return check_topic_name(value, key.name, where)
        return check_frame_name(value, key.name, where)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise RobotFileError(f'{where}{key.name} is {value!r}: a number is needed '
                             f'({key.meaning})')
    if isinstance(value, int):
        raise RobotFileError(f'{where}{key.name} is {value}: write {value}.0 (ROS refuses an '
                             'integer for a double parameter)')
    zero = f'; 0 = {key.zero}' if key.zero else ''
    low = key.low if key.low is not None else -math.inf
    high = key.high if key.high is not None else math.inf
    if not (math.isfinite(value) and low <= value <= high):
        rng = f'{"above 0" if low > 0 and low < 1e-3 else f"at least {low:g}"}' + \
            f' and at most {high:g}'
        raise RobotFileError(f'{where}{key.name} is {value!r}: it must be {rng} '
                             f'({key.meaning}{zero})')
    return float(value)


def parse_robot_parameters(values: Mapping[str, Any], where: str = '') -> RobotConfig:
    """Check the tracker parameters of a robot file and make a :class:`RobotConfig`.

    Parameters
    ----------
    values : mapping
        The ``ros__parameters`` of the tracker section, by name.
    where : str, optional
        The file they come from (for the messages and :attr:`RobotConfig.source`).

    Returns
    -------
    RobotConfig
        Keys left out take the tracker's defaults.

    Raises
    ------
    RobotFileError
        An unknown key (the message lists the known ones), a wrong type or a value out of
        range.
    """
    prefix = f'{where}: ' if where else ''
    unknown = [k for k in values if k not in _BY_NAME]
    if unknown:
        raise RobotFileError(
            f'{prefix}unknown key(s) {", ".join(map(str, unknown))}; a robot file knows '
            f'{", ".join(_BY_NAME)} (other tracker parameters go in the gain file or '
            'another --params-file)')
    checked = {name: _value(_BY_NAME[name], v, prefix) for name, v in values.items()}
    return RobotConfig(**checked, source=where)


def _section(data: Mapping[str, Any], where: str) -> Mapping[str, Any]:
    """The tracker's ``ros__parameters`` of a parsed robot file (its only section)."""
    layout = (f'a robot file has one section: /**/{NODE}: ros__parameters: {{...}} '
              '(see config/robot.yaml)')
    others = [str(k) for k in data if node_key(str(k)).rsplit('/', 1)[-1] != NODE]
    if others:
        raise RobotFileError(f'{where}: section(s) {", ".join(others)} not allowed: {layout}')
    sections = list(data.values())
    if len(sections) != 1:
        raise RobotFileError(f'{where}: {len(sections)} tracker sections: {layout}')
    section = sections[0]
    if not isinstance(section, Mapping) or set(section) != {'ros__parameters'} \
            or not isinstance(section['ros__parameters'], Mapping):
        raise RobotFileError(f'{where}: the tracker section must hold ros__parameters, a '
                             f'mapping of parameters: {layout}')
    return section['ros__parameters']


def load_robot_file(path: str | os.PathLike[str] | None = None) -> RobotConfig:
    """Read and check a robot file (default: the shipped ``config/robot.yaml``).

    Parameters
    ----------
    path : path-like, optional
        The robot file.

    Returns
    -------
    RobotConfig

    Raises
    ------
    RobotFileError
        The file cannot be read or is not YAML, has another layout than one tracker
        section, an unknown key, a wrong type or a value out of range.
    """
    p = Path(path) if path is not None else robot_file()
    data = read_yaml(p, 'robot file', error=RobotFileError, mapping=True)
    return parse_robot_parameters(_section(data, str(p)), str(p))


def identified_limits(ident: Identification) -> dict[str, float]:
    """The base's limits an identification found, as robot-file keys.

    Parameters
    ----------
    ident : Identification
        From ``identify`` (:func:`~.control.identification.identify.identify_latency` or
        :func:`~.control.identification.records.read_identification`).

    Returns
    -------
    dict
        ``max_linear_accel`` and ``max_angular_accel`` where the recording showed the limit
        binding (> 0); a limit not seen (0 = unknown) is left out, so that writing it never
        switches off a limit the file knows.
    """
    found = {'max_linear_accel': float(ident.max_linear_accel),
             'max_angular_accel': float(ident.max_angular_accel)}
    return {k: float(f'{v:.4g}') for k, v in found.items() if math.isfinite(v) and v > 0}


@dataclass(frozen=True)
class Change:
    """One key :func:`update_robot_file` set: its old value (None: absent) and new one."""

    key: str
    old: Any
    new: Any

    def __str__(self) -> str:
        old = 'absent' if self.old is None else repr(self.old)
        return f'{self.key}: {old} -> {self.new!r}'


_NOTE = re.compile(r'\s*\[[^\]]*\]\s*$')


def update_robot_file(path: str | os.PathLike[str], values: Mapping[str, Any], *,
                      note: str = '', template: str | os.PathLike[str] | None = None,
                      only_unknown: bool = False) -> list[Change]:
    """Set ``values`` in the robot file ``path``, keeping its other lines and comments.

    A missing ``path`` is first made from ``template`` (default: the shipped
    ``config/robot.yaml``, comments included).  The file must be a valid robot file before
    and is checked again before it is written (never half an edit: written to a temporary
    file and renamed).  A key already there keeps its place and comment; ``note`` is put in
    brackets at the end of that comment (replacing an earlier bracketed note), e.g.
    ``# ... 0 = unknown [identified from runs/x/bag]``.  A key not there is appended.

    Parameters
    ----------
    path : path-like
        The robot file to update (or create).
    values : mapping
        Robot-file keys (:data:`KEYS`) and their new values (checked as in a file).
    note : str, optional
        Where the values come from, for the comment of each changed key.
    template : path-like, optional
        The file a missing ``path`` starts from.
    only_unknown : bool, optional
        Set a key only where the file does not know it (absent, or 0 where 0 means
        unknown or none): a value the user wrote is kept.  Default: every key is set (the
        CLI's ``--robot-file``: a limit the recording shows binding is what the base does).

    Returns
    -------
    list of Change
        The keys whose value changed (an unchanged key keeps its comment too).

    Raises
    ------
    RobotFileError
        ``path`` (or the template) is not a valid robot file, or a value is refused.
    """
    from ruamel.yaml import YAML
    from ruamel.yaml.error import YAMLError

    p = Path(path)
    source = p if p.exists() else Path(template) if template is not None else robot_file()
    load_robot_file(source)                          # a valid robot file to start from
    parse_robot_parameters(values, f'{p} (new values)')
    yaml = YAML()                                    # round trip: comments and order kept
    yaml.width = 4096
    try:
        data = yaml.load(source.read_text(encoding='utf-8'))
    except (OSError, YAMLError) as exc:              # load_robot_file read it just now
        raise RobotFileError(f'{source}: cannot read robot file ({exc})') from None
    params = next(iter(data.values()))['ros__parameters']
    changes = []
    for key, new in values.items():
        value = float(new) if _BY_NAME[key].kind is float else new
        old = _plain(params.get(key))
        if key in params and old == value and type(old) is type(value):
            continue
        if only_unknown and key in params and not (_BY_NAME[key].zero and old == 0):
            continue
        changes.append(Change(key, None if key not in params else old, value))
        params[key] = value
        if note:
            _annotate(params, key, note)
    out = io.StringIO()
    yaml.dump(data, out)
    text = out.getvalue()
    tmp = p.with_name(f'.{p.name}.tmp')
    try:
        tmp.write_text(text, encoding='utf-8')
        load_robot_file(tmp)                          # never write what cannot be read back
        os.replace(tmp, p)
    except OSError as exc:
        raise RobotFileError(f'{p}: cannot write robot file ({exc.strerror or exc})') from None
    finally:
        tmp.unlink(missing_ok=True)
    return changes


def _plain(value: Any) -> Any:
    """A ruamel scalar (``ScalarFloat``, ``ScalarString`` ...) as the builtin it stands for."""
    for kind in (bool, float, int, str):
        if isinstance(value, kind):
            return kind(value)
    return value


def _annotate(params: Any, key: str, note: str) -> None:
    """Put ``[note]`` at the end of ``key``'s end-of-line comment (ruamel CommentedMap)."""
    entry = params.ca.items.get(key)
    token = entry[2] if entry and len(entry) > 2 else None
    if token is not None and token.value.lstrip().startswith('#'):
        # the token holds the end-of-line comment and the comment lines after it
        first, _, rest = token.value.partition('\n')
        token.value = f'{_NOTE.sub("", first)} [{note}]\n{rest}'
    else:
        params.yaml_add_eol_comment(f'[{note}]', key)
