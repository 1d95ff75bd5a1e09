"""How the suite itself runs (``test/conftest.py``, ``setup.cfg``): the ROS-free tests on
every core, whole modules per worker; every run that may select ROS tests serial."""
import re
import subprocess
import sys

import pytest

from conftest import ROOT, mark_expression_may_select

MODULES = ['test/control/test_model.py', 'test/control/test_trajectory.py']


def _pytest(*args: str) -> str:
    proc = subprocess.run([sys.executable, '-m', 'pytest', '-p', 'no:cacheprovider', '-v',
                           '-n', '2', *args, *MODULES], capture_output=True, text=True,
                          cwd=ROOT, timeout=120)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return proc.stdout


def test_a_run_that_may_select_ros_tests_is_serial():
    """Even with -n 2: no xdist worker runs anything, the header says why."""
    out = _pytest()
    assert 'one test after another (pytest-xdist off)' in out
    assert re.search(r'^test/control/test_model.py::\S+ PASSED', out, flags=re.M)
    assert '[gw' not in out


def test_the_ros_free_run_gives_each_worker_whole_modules():
    out = _pytest('-m', 'not ros')
    workers: dict[str, set[str]] = {}
    for gw, module in re.findall(r'^\[(gw\d+)\] .*PASSED (\S+?)::', out, flags=re.M):
        workers.setdefault(module, set()).add(gw)
    assert sorted(workers) == MODULES
    assert all(len(gws) == 1 for gws in workers.values()), workers


@pytest.mark.parametrize('expr, ros', [
    ('', True), ('ros', True), ('slow', True), ('not slow', True), ('not ros or slow', True),
    ('not (not ros)', True), ('ros or not ros', True), ('not ros and slow or ros', True),
    ('not ros (', True),                                    # pytest reports the syntax error
    ('not ros', False), ('not (ros)', False), ('not ros and not slow', False),
    ('(not ros) and slow', False)])
def test_which_mark_expressions_may_select_ros_tests(expr, ros):
    """From the expression, not its text: serial and every ROS module collected iff True."""
    assert mark_expression_may_select(expr, 'ros') is ros
