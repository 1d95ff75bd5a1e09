"""Ctrl-C while a node process starts (rclpy, numpy, messages importing): exit 0, no output.

The console scripts and ``run`` start the nodes through ``nodes.entry``, which imports the
node module itself: a SIGINT before :func:`nodes.common.run` has switched KeyboardInterrupt
off ends the node as a SIGINT while spinning does (exit 0), not with a traceback.
"""
from __future__ import annotations

import signal
import subprocess
import sys
import time

import pytest

from conftest import ROOT


def _loaded(pid: int, marker: str) -> bool:
    try:
        with open(f'/proc/{pid}/maps') as fh:
            return marker in fh.read()
    except OSError:
        return False


@pytest.mark.parametrize('node, delay', [('plant', 0.0), ('tracker', 0.0), ('reference', 0.0),
                                         ('recorder', 0.0), ('plant', 0.03), ('tracker', 0.1)])
def test_ctrl_c_while_the_node_imports_is_a_clean_exit(node, delay, ros_env, tmp_path):
    args = ['--ros-args', '-p', f'output:={tmp_path / "bag"}'] if node == 'recorder' else []
    proc = subprocess.Popen([sys.executable, '-m', 'nonfragile_tracker.nodes.entry', node,
                             *args], cwd=ROOT, env=ros_env, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)
    deadline = time.monotonic() + 60
    while not _loaded(proc.pid, '_multiarray_umath') and proc.poll() is None \
            and time.monotonic() < deadline:
        time.sleep(0.002)
    time.sleep(delay)
    proc.send_signal(signal.SIGINT)
    out, _ = proc.communicate(timeout=60)
    assert proc.returncode == 0, out
    assert 'Traceback' not in out and 'KeyboardInterrupt' not in out, out


def test_unknown_node_is_a_usage_error(ros_env):
    proc = subprocess.run([sys.executable, '-m', 'nonfragile_tracker.nodes.entry', 'nope'],
                          cwd=ROOT, env=ros_env, capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2 and "unknown node 'nope'" in proc.stderr
