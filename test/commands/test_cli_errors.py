"""Every command, fed its class of bad numbers and bad files: exit 2 with a message, no traceback.

Most rows call ``cli.main`` in-process (argparse usage errors raise ``SystemExit(2)``);
a few run the real entry point in a subprocess to see what a user sees.
"""
from __future__ import annotations

import os
import subprocess
import sys

import pytest

from nonfragile_tracker import cli
from nonfragile_tracker.errors import EXIT_BAD_INPUT, EXIT_INTERRUPTED

from conftest import CONFIG, ROOT

PAPER = str(CONFIG / 'paper_problem.yaml')
GAINS = str(CONFIG / 'tracker_gains.yaml')

BAD_NUMBERS = ['-1', '0', 'nan', 'inf', '-inf', 'abc', '']
#: option -> the commands (with their other arguments) that take it as a number > 0
NUMBER_OPTIONS = [
    (['synthesize', PAPER], '--gain-bound'),
    (['design', PAPER, '--objective', 'decay'], '--norm'),
    (['design', PAPER, '--objective', 'scale'], '--norm'),
    (['delay-dependent', PAPER], '--delay'),
    (['delay-dependent', PAPER, '--max-delay'], '--gain-bound'),
    (['run', '--no-record'], '--duration'),
    (['reproduce', '--no-ros'], '--duration'),
]


@pytest.fixture(scope='module')
def bad(tmp_path_factory):
    """One file (or directory) of every bad kind, by name."""
    d = tmp_path_factory.mktemp('bad')
    (d / 'junk.bin').write_bytes(b'\x00\xff\xfe\x01garbage\x89PNG\r\n\x1a\n')
    (d / 'empty.yaml').write_text('')
    (d / 'broken.yaml').write_text('A: [[0, 1], [0, 0]\nB: {\n')
    (d / 'scalar.yaml').write_text('just a string\n')
    (d / 'list.yaml').write_text('[1, 2, 3]\n')
    (d / 'a_directory').mkdir()
    files = {p.name: str(p) for p in d.iterdir()}
    files['missing.yaml'] = str(d / 'missing.yaml')
    files['root'] = str(d)
    return files


def run_main(argv, capsys):
    """(exit code, stdout, stderr) of ``cli.main(argv)`` in this process."""
    try:
        code = cli.main(argv)
    except SystemExit as exc:           # argparse usage errors
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.parametrize('value', BAD_NUMBERS)
@pytest.mark.parametrize('argv, option', NUMBER_OPTIONS,
                         ids=[' '.join(a[:1] + a[2:] + [o]) for a, o in NUMBER_OPTIONS])
def test_bad_numbers_are_usage_errors(capsys, tmp_path, argv, option, value):
    argv = argv + [option, value]
    if argv[0] in ('run', 'reproduce'):
        argv += ['--out', str(tmp_path / 'out')]
    code, out, err = run_main(argv, capsys)
    assert code == EXIT_BAD_INPUT, (argv, out, err)
    assert f'argument {option}' in err and 'usage:' in err and 'Traceback' not in err
    assert not (tmp_path / 'out').exists()        # nothing started, nothing written


FILE_KINDS = {
    'junk.bin': 'not a text file',
    'empty.yaml': 'empty file',
    'broken.yaml': 'not valid YAML (line',
    'scalar.yaml': 'expected a',
    'list.yaml': 'expected a',
    'a_directory': 'Is a directory',
    'missing.yaml': 'No such file',
}
#: commands and where the bad file goes ({} is replaced by the file)
FILE_SLOTS = [
    ['synthesize', '{}'],
    ['design', '{}', '--objective', 'min-norm'],
    ['delay-dependent', '{}', '--max-delay'],
    ['analyse', '{}', '--paper', '--no-margins'],
    ['margins', '{}', '--paper'],
    ['analyse', PAPER, '--gains', '{}', '--no-margins'],
    ['margins', PAPER, '--gains', '{}'],
    ['run', '--scenario', '{}', '--no-record'],
    ['run', '--gains', '{}', '--no-record'],
]


#: an empty scenario file is valid (every node keeps its defaults): not a bad file
FILE_CASES = [(slot, kind) for slot in FILE_SLOTS for kind in sorted(FILE_KINDS)
              if not (kind == 'empty.yaml' and '--scenario' in slot)]


@pytest.mark.parametrize('slot, kind', FILE_CASES, ids=[
    ' '.join(s).replace(PAPER, 'PAPER').replace('{}', k) for s, k in FILE_CASES])
def test_bad_files_exit_2_naming_the_file(capsys, tmp_path, bad, slot, kind):
    argv = [bad[kind] if a == '{}' else a for a in slot]
    if argv[0] == 'run':
        argv += ['--out', str(tmp_path / 'runs')]
    code, out, err = run_main(argv, capsys)
    assert code == EXIT_BAD_INPUT, (argv, out, err)
    assert err.startswith('error: ') and bad[kind] in err and FILE_KINDS[kind] in err, err
    assert 'Traceback' not in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / 'runs').exists()


@pytest.mark.parametrize('cmd', ['report', 'repair'])
@pytest.mark.parametrize('kind, message', [
    ('junk.bin', 'is a file'), ('a_directory', ''), ('missing.yaml', ''), ('empty.yaml', '')])
def test_bag_commands_reject_files_and_empty_directories(capsys, bad, cmd, kind, message):
    code, out, err = run_main(['bag', cmd, bad[kind]], capsys)
    assert code == EXIT_BAD_INPUT and err.startswith('error: ') and bad[kind] in err, err
    assert message in err and 'Traceback' not in err


def test_problem_options_are_validated(capsys, tmp_path):
    text = (CONFIG / 'paper_problem.yaml').read_text()
    for bad_value, message in (('-1', 'options.gain_bound'), ('.nan', 'options.gain_bound'),
                               ('"eight"', 'options.gain_bound')):
        p = tmp_path / 'p.yaml'
        p.write_text(text + f'\n  gain_bound: {bad_value}\n' if 'gain_bound:' not in text else
                     '\n'.join(line if not line.strip().startswith('gain_bound:') else
                               f'  gain_bound: {bad_value}' for line in text.splitlines()))
        code, _, err = run_main(['synthesize', str(p)], capsys)
        assert code == EXIT_BAD_INPUT and message in err and 'Traceback' not in err, err


def test_design_without_a_norm_says_which_option(capsys, tmp_path):
    text = '\n'.join(line for line in (CONFIG / 'paper_problem.yaml').read_text().splitlines()
                     if not line.strip().startswith('gain_bound:'))
    p = tmp_path / 'p.yaml'
    p.write_text(text)
    code, _, err = run_main(['design', str(p), '--objective', 'decay'], capsys)
    assert code == EXIT_BAD_INPUT and '--norm' in err and 'Traceback' not in err


def test_outputs_that_cannot_be_written_exit_2(capsys, bad, tmp_path):
    code, _, err = run_main(['reproduce', '--no-ros', '--out', bad['junk.bin']], capsys)
    assert code == EXIT_BAD_INPUT and 'not a directory' in err
    code, _, err = run_main(['run', '--no-record', '--out', bad['junk.bin']], capsys)
    assert code == EXIT_BAD_INPUT and bad['junk.bin'] in err
    code, _, err = run_main(['analyse', PAPER, '--gains', GAINS, '--no-margins', '--json',
                             bad['a_directory']], capsys)
    assert code == EXIT_BAD_INPUT and bad['a_directory'] in err and 'Traceback' not in err
    code, _, err = run_main(['analyse', PAPER, '--no-margins'], capsys)
    assert code == EXIT_BAD_INPUT and '--gains FILE' in err
    code, _, err = run_main(['run', '--no-record', '--delta', 'Delta_9', '--out',
                             str(tmp_path / 'runs')], capsys)
    assert code == EXIT_BAD_INPUT and 'Delta_1, Delta_2' in err and 'Delta_9' in err
    assert not (tmp_path / 'runs').exists()


def test_unknown_commands_and_options_are_usage_errors(capsys):
    for argv in ([], ['nope'], ['golden', '--bogus'], ['bag'],
                 ['design', PAPER, '--objective', 'fastest']):
        code, _, err = run_main(argv, capsys)
        assert code == EXIT_BAD_INPUT and 'usage:' in err and 'Traceback' not in err


def test_a_bug_is_one_internal_error_line_and_ctrl_c_is_130(capsys, monkeypatch, bad):
    from nonfragile_tracker.commands import bag

    def boom(args):
        raise ZeroDivisionError('division by zero')
    monkeypatch.setattr(bag, 'cmd_report', boom)
    monkeypatch.delenv('NONFRAGILE_DEBUG', raising=False)
    code, _, err = run_main(['bag', 'report', bad['root']], capsys)
    assert code == 1 and err.startswith('internal error: ZeroDivisionError: division by zero')
    assert 'NONFRAGILE_DEBUG=1' in err and len(err.strip().splitlines()) == 1

    def interrupted(args):
        raise KeyboardInterrupt
    monkeypatch.setattr(bag, 'cmd_report', interrupted)
    code, out, err = run_main(['bag', 'report', bad['root']], capsys)
    assert code == EXIT_INTERRUPTED and err == ''


def _entry_point(args, env_extra=None):
    env = dict(os.environ, PYTHONPATH=str(ROOT), **(env_extra or {}))
    env.pop('NONFRAGILE_DEBUG', None) if not env_extra else None
    return subprocess.run([sys.executable, '-m', 'nonfragile_tracker.cli', *args],
                          capture_output=True, text=True, cwd=ROOT, timeout=120, env=env)


@pytest.mark.parametrize('args, message', [
    (['synthesize', PAPER, '--gain-bound', '-1'], 'argument --gain-bound: expected a number > 0'),
    (['delay-dependent', PAPER, '--delay', '0'], 'argument --delay: expected a number > 0'),
    (['synthesize', '{junk.bin}'], 'not a text file'),
    (['run', '--scenario', '{broken.yaml}', '--no-record'], 'not valid YAML'),
])
def test_the_real_entry_point(bad, tmp_path, args, message):
    args = [bad[a[1:-1]] if a.startswith('{') else a for a in args]
    if args[0] == 'run':
        args += ['--out', str(tmp_path)]
    proc = _entry_point(args)
    assert proc.returncode == EXIT_BAD_INPUT, proc.stderr
    assert message in proc.stderr and 'Traceback' not in proc.stderr and proc.stdout == ''


def test_debug_switch_shows_the_traceback_of_a_bug(tmp_path):
    code = ('import sys; from nonfragile_tracker import cli; from nonfragile_tracker.commands '
            'import bag; bag.cmd_report = lambda a: 1 / 0; '
            "sys.exit(cli.main(['bag', 'report', 'x']))")
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    env.pop('NONFRAGILE_DEBUG', None)
    quiet = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                           cwd=ROOT, timeout=60, env=env)
    assert quiet.returncode == 1 and 'Traceback' not in quiet.stderr
    assert quiet.stderr.startswith('internal error: ZeroDivisionError')
    env['NONFRAGILE_DEBUG'] = '1'
    loud = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                          cwd=ROOT, timeout=60, env=env)
    assert loud.returncode == 1 and 'Traceback' in loud.stderr and 'ZeroDivisionError' in loud.stderr


@pytest.mark.ros
def test_run_with_a_parameter_a_node_refuses_exits_2_naming_node_and_parameter(tmp_path, capsys,
                                                                                monkeypatch):
    """The nodes validate their parameters: a refused one is bad input (2), not a run failure."""
    from conftest import unique_domain_id
    monkeypatch.setenv('ROS_DOMAIN_ID', str(unique_domain_id('cli_errors')))
    scenario = tmp_path / 'scenario.yaml'
    scenario.write_text((CONFIG / 'paper_scenario.yaml').read_text().replace(
        '    dt: 0.01\n    tau: 0.2', '    dt: -1.0\n    tau: 0.2', 1))
    assert 'dt: -1.0' in scenario.read_text()
    code, out, err = run_main(['run', '--scenario', str(scenario), '--no-record',
                               '--out', str(tmp_path / 'runs')], capsys)
    assert code == EXIT_BAD_INPUT, (out, err)
    assert err.startswith('error: plant:') and 'dt' in err and '-1.0' in err
    assert 'Traceback' not in err + out
