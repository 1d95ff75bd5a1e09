"""``ros2 run`` works after ``colcon build`` under every setuptools colcon accepts.

colcon-core requires setuptools < 80, so a workspace venv gets 79.x while Ubuntu 24.04
(Jazzy) ships 68.1.2.  setuptools 79's ``build_scripts`` wrote plain ``scripts=`` with the
wheel placeholder ``#!python`` and ``ros2 run`` failed with FileNotFoundError.  The
executables are now console scripts whose node wrappers setup.py writes lean (see its
docstring).  Each version here builds the package with the pinned colcon (normal and
``--symlink-install``) and every installed executable is started as ``ros2 run`` starts it:
``exec`` of the installed file, which must reach the package's own clear refusal (exit 2,
no traceback); a SIGINT during a node's start-up ends it with 0 and no traceback.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from conftest import ROOT, mapped

pytestmark = [pytest.mark.ros, pytest.mark.slow]

COLCON = Path(sys.executable).parent / 'colcon'
#: Where ``make`` (the venv's recipe, COLCON_SETUPTOOLS) installs each setuptools.
SETUPTOOLS_DIR = Path(sys.prefix) / 'colcon-setuptools'
#: Jazzy's (Ubuntu 24.04) and the newest that colcon-core accepts (< 80).
SETUPTOOLS = ('68.1.2', '79.0.1')
#: A bad parameter per node and the words of its refusal.
REFUSALS = {
    'tracker': (['-p', 'K:=[.nan, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]'], 'K'),
    'plant': (['-p', 'dt:=-1.0'], 'dt'),
    'reference': (['-p', 'path:=square'], "unknown path 'square'"),
    'recorder': (['-p', 'chunk_size:=0'], 'chunk_size must be'),
}


@pytest.fixture(scope='module', params=SETUPTOOLS)
def installed(request, tmp_path_factory):
    """(prefix, env) of a colcon install built with setuptools ``request.param``."""
    version = request.param
    base = tmp_path_factory.mktemp(f'setuptools{version}')
    target = SETUPTOOLS_DIR / version
    assert (target / 'setuptools').is_dir(), (
        f'setuptools {version} is not in {target}: the venv predates it; '
        'rm .venv/.installed and run make again')
    # setuptools on PYTHONPATH comes before the venv's own in colcon and in setup.py
    env = dict(os.environ, PYTHONDONTWRITEBYTECODE='1', PYTHONPATH=str(target))
    seen = subprocess.run([sys.executable, '-c',
                           'import setuptools; print(setuptools.__version__)'],
                          capture_output=True, text=True, env=env, timeout=60)
    assert seen.stdout.strip() == version, seen.stdout + seen.stderr
    prefixes = {}
    for mode, extra in (('install', []), ('symlink', ['--symlink-install'])):
        ws = base / mode
        ws.mkdir()
        proc = subprocess.run(
            [str(COLCON), '--log-base', str(ws / 'log'), 'build', '--paths', str(ROOT),
             '--build-base', str(ws / 'build'), '--install-base', str(ws / 'install'), *extra],
            capture_output=True, text=True, env=env, cwd=ws, timeout=300)
        assert proc.returncode == 0, proc.stdout + proc.stderr
        prefixes[mode] = ws / 'install' / 'nonfragile_tracker'
    return version, prefixes


def _ros2_run(prefix: Path, exe: str, *args: str) -> list[str]:
    """``ros2 run nonfragile_tracker EXE ARGS`` in a shell that sourced the workspace.

    ``ros2 run`` finds ``lib/<package>/EXE`` in the sourced prefix and execs it; the shell
    ``exec``s it too, so a signal sent to the process reaches the executable.
    """
    setup = prefix.parent / 'setup.sh'
    return ['sh', '-c', f'. "{setup}" && exec "$0" "$@"',
            str(prefix / 'lib' / 'nonfragile_tracker' / exe), *args]


@pytest.fixture
def run_env(ros_env):
    """``ros_env`` without the source tree on PYTHONPATH (setup.sh adds the install space)."""
    return {k: v for k, v in ros_env.items() if k != 'PYTHONPATH'}


def test_installed_executables_start_and_refuse_clearly(installed, tmp_path, run_env):
    version, prefixes = installed
    for mode, prefix in prefixes.items():
        lib = prefix / 'lib' / 'nonfragile_tracker'
        for node, (args, words) in REFUSALS.items():
            first = (lib / node).read_text().splitlines()[0]
            interpreter = first[2:].split()[0]
            assert first.startswith('#!/') and os.access(interpreter, os.X_OK), (version, first)
            out = subprocess.run(_ros2_run(prefix, node, '--ros-args', *args),
                                 capture_output=True, text=True, env=run_env, cwd=tmp_path,
                                 timeout=120)
            where = f'setuptools {version} ({mode}), {node}'
            assert out.returncode == 2, (where, out.stderr)
            assert words in out.stderr and 'Traceback' not in out.stderr, (where, out.stderr)
        out = subprocess.run(_ros2_run(prefix, 'nonfragile_tracker', 'synthesize',
                                       str(tmp_path / 'missing.yaml')),
                             capture_output=True, text=True, env=run_env, cwd=tmp_path,
                             timeout=120)
        assert out.returncode == 2 and 'missing.yaml' in out.stderr, (version, mode, out.stderr)


#: Moments of a node's start-up, as the first shared object mapped after them: the entry's
#: main() notes stop signals before it imports the node module (numpy, then rclpy).
MOMENTS = ('_multiarray_umath', '_rclpy_pybind11')


def test_sigint_while_an_installed_node_starts_ends_it_cleanly(installed, tmp_path, run_env):
    """The lean wrapper imports only ``nodes.entry`` before it notes stop signals."""
    version, prefixes = installed
    prefix = prefixes['install']
    assert 'importlib' not in (prefix / 'lib' / 'nonfragile_tracker' / 'plant').read_text()
    for marker in MOMENTS:
        proc = subprocess.Popen(_ros2_run(prefix, 'plant', '--ros-args', '-p', 'mode:=realtime'),
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                env=run_env, cwd=tmp_path)
        deadline = time.monotonic() + 60
        while not mapped(proc.pid, marker) and proc.poll() is None \
                and time.monotonic() < deadline:
            time.sleep(0.002)
        assert proc.poll() is None, (version, marker, proc.communicate())
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=60)
        assert proc.returncode == 0, (version, marker, err)
        assert 'Traceback' not in err and 'KeyboardInterrupt' not in err, (version, marker, err)
