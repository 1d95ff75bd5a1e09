"""What several commands share: the output-file options and their check before any work.

A command that writes files refuses an existing one without ``--force`` and a missing
directory before it computes anything (exit 2 through ``cli.main``), with one message
for every command.

See doc/cli.md, section "Exit codes and errors".
"""
from __future__ import annotations

import argparse
from pathlib import Path

from ..errors import InputError

__all__ = ['add_report_outputs', 'check_outputs', 'check_robot_file', 'HelpFormatter',
           'write_robot_file']

TYPE_CHECKING = False
if TYPE_CHECKING:
    #: The object ``ArgumentParser.add_subparsers()`` returns: each command module's
    #: ``register`` adds its sub-commands to it.
    Subparsers = argparse._SubParsersAction[argparse.ArgumentParser]
else:
    Subparsers = argparse._SubParsersAction


class HelpFormatter(argparse.HelpFormatter):
    """The ``--help`` of every command: an option's default is shown unless its help says it.

    ``(default: X)`` is appended to the help of an option whose default is a value (not
    None, a flag's bool or an empty list) and whose help does not already name its default.
    """

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ''
        d = action.default
        if (not action.option_strings or 'default' in text or d is None
                or isinstance(d, bool) or d is argparse.SUPPRESS or d == []):
            return text
        return text + ' (default: %(default)s)'


def check_outputs(force: bool, *outputs: str | None) -> None:
    """Refuse output files that exist (unless ``force``) or whose directory does not.

    Parameters
    ----------
    force : bool
        ``--force``: an existing file may be overwritten.
    *outputs : str or None
        The output paths given on the command line; ``None`` (an option left out) is
        skipped.

    Raises
    ------
    InputError
        If an output exists and ``force`` is false, or its directory does not exist.
    """
    for out in outputs:
        if not out:
            continue
        if Path(out).exists() and not force:
            raise InputError(f'{out} exists; pass --force to overwrite it')
        if not Path(out).resolve().parent.is_dir():
            raise InputError(f'{out}: directory {Path(out).resolve().parent} does not exist')


def add_report_outputs(p: argparse.ArgumentParser, json_help: str, plot_help: str) -> None:
    """``--json OUT``, ``--plot OUT.png`` and ``--force`` (checked by :func:`check_outputs`).

    Parameters
    ----------
    p : argparse.ArgumentParser
        The sub-command's parser.
    json_help, plot_help : str
        What the command writes as JSON and as a plot.
    """
    p.add_argument('--json', metavar='OUT', help=json_help)
    p.add_argument('--plot', metavar='OUT.png', help=plot_help)
    p.add_argument('--force', action='store_true', help='overwrite --json/--plot files')


def check_robot_file(path: str | None) -> None:
    """Before any work: a ``--robot-file`` that exists must be a valid robot file.

    One that does not exist yet will be made from the shipped ``config/robot.yaml``; its
    directory must exist.

    Parameters
    ----------
    path : str or None
        The ``--robot-file`` given (``None``: none).

    Raises
    ------
    InputError
        The file is not a valid robot file
        (:class:`~nonfragile_tracker.interface.robot.RobotFileError`) or its directory does not
        exist.
    """
    if not path:
        return
    from ..interface.robot import load_robot_file
    if Path(path).exists():
        load_robot_file(path)
    elif not Path(path).resolve().parent.is_dir():
        raise InputError(f'{path}: directory {Path(path).resolve().parent} does not exist')


def write_robot_file(path: str, values: dict[str, float], note: str) -> None:
    """Write identified values into the robot file ``path`` and say what changed.

    :func:`nonfragile_tracker.interface.robot.update_robot_file`: the other keys and the
    comments are kept; a missing file is made from the shipped ``config/robot.yaml``.

    Parameters
    ----------
    path : str
        The robot file (``--robot-file``).
    values : dict
        Robot-file keys and values (:func:`nonfragile_tracker.interface.robot.identified_limits`).
    note : str
        Where they come from (put in brackets in each changed key's comment).
    """
    from ..interface.robot import update_robot_file
    existed = Path(path).exists()
    changes = update_robot_file(path, values, note=note)
    head = f'robot file {path}' + ('' if existed else ' (new: a copy of the shipped '
                                   'config/robot.yaml; edit its topics, frames and limits)')
    if changes:
        print(f'{head}: ' + ', '.join(map(str, changes)))
    elif values:
        print(f'{head}: already has ' + ', '.join(f'{k} = {v!r}' for k, v in values.items()))
    else:
        print(f'{head}: no acceleration limit seen to bind in the recording; nothing written '
              '(0 = unknown stays)')
