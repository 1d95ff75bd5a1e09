"""How the suite itself runs (``test/conftest.py``, ``setup.cfg``): every test but the
real-time ones on every core, whole modules per worker, each worker with ROS domains of its
own; the real-time ones alone (two workers in make test); a run that may select real-time
tests together with others serial."""
import re
import subprocess
import sys

import pytest

from conftest import ROOT, domain_ids, mark_expression_may_select, serial_run

MODULES = ['test/control/test_model.py', 'test/control/test_trajectory.py']


def _pytest(*args: str, modules=MODULES) -> str:
    proc = subprocess.run([sys.executable, '-m', 'pytest', '-p', 'no:cacheprovider', '-v',
                           '-n', '2', *args, *modules], capture_output=True, text=True,
                          cwd=ROOT, timeout=120)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return proc.stdout


def test_a_run_that_may_select_realtime_tests_is_serial():
    """Even with -n 2: no xdist worker runs anything, the header says why."""
    out = _pytest()
    assert 'one test after another (pytest-xdist off)' in out
    assert re.search(r'^test/control/test_model.py::\S+ PASSED', out, flags=re.M)
    assert '[gw' not in out


def test_ros_tests_without_realtime_ones_run_on_the_workers():
    """``-m "not realtime"`` (make test's first part) spreads ROS modules over the workers."""
    out = _pytest('-m', 'not realtime', modules=MODULES + ['test/nodes/test_node_parameters.py'])
    assert re.search(r'^\[gw\d\] .*PASSED test/nodes/test_node_parameters.py::', out, flags=re.M)
    assert 'one test after another' not in out


def test_workers_have_ros_domains_of_their_own(monkeypatch):
    seen = []
    for worker in ('gw0', 'gw1'):
        monkeypatch.setenv('PYTEST_XDIST_WORKER', worker)
        monkeypatch.setenv('PYTEST_XDIST_WORKER_COUNT', '2')
        ids = domain_ids('x', 6)
        assert len(set(ids)) == 6
        seen.append(set(ids))
    assert all(100 <= d < 150 for d in seen[0]) and all(150 <= d < 200 for d in seen[1])


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
    """From the expression, not its text: every ROS module collected iff True (the same
    test decides a serial run for the ``realtime`` mark)."""
    assert mark_expression_may_select(expr, 'ros') is ros


@pytest.mark.parametrize('expr, serial', [
    ('', True), ('ros', True), ('realtime', True), ('slow', True), ('not slow', True),
    ('not ros', False), ('not realtime', False), ('ros and not realtime', False),
    ('not (ros or slow)', False), ('not ros or realtime', True)])
def test_which_mark_expressions_may_select_realtime_tests(expr, serial):
    """A real-time test is a ROS test too: ``-m "not ros"`` selects none."""
    assert mark_expression_may_select(expr, 'realtime', 'ros') is serial


@pytest.mark.parametrize('expr, serial', [
    ('', True), ('ros', True), ('not slow', True), ('realtime or slow', True),
    ('realtime', False), ('realtime and slow', False), ('ros and realtime', False),
    ('not ros', False), ('not realtime', False)])
def test_real_time_tests_alone_may_use_the_workers(expr, serial):
    """Serial only when real-time tests may run together with others (make test's second
    part, ``-m realtime``, runs on three workers)."""
    assert serial_run(expr) is serial


@pytest.mark.parametrize('expr, source, skipped', [
    ('realtime', 'def test_a(): pass\n', True),
    ('realtime', '@pytest.mark.realtime\ndef test_a(): pass\n', False),
    ('numerical and not realtime', 'pytestmark = pytest.mark.numerical\n', False),
    ('numerical and not realtime', '@pytest.mark.slow\ndef test_a(): pass\n', True),
    ('not realtime', 'def test_a(): pass\n', False),
    ('not numerical', 'pytestmark = pytest.mark.numerical\n', False),   # a test may lack it
    ('ros', 'def test_a(): pass\n', True),
    ('ros', '@pytest.mark.realtime\ndef test_a(): pass\n', False),      # realtime is ros
    ('', 'def test_a(): pass\n', False),
    ('numerical and', 'def test_a(): pass\n', False)])                  # pytest reports it
def test_a_module_no_test_of_which_the_expression_selects_is_not_imported(
        tmp_path, expr, source, skipped):
    """make test's second-kernel and real-time passes import the modules they select from,
    judged by the marks conftest gives and the module's text names."""
    import types
    import conftest
    module = tmp_path / 'test_planted.py'
    module.write_text('import pytest\n' + source)
    config = types.SimpleNamespace(getoption=lambda name: expr)
    assert (conftest.pytest_ignore_collect(module, config) is True) is skipped


def test_a_mark_the_skip_could_not_see_stops_the_run(tmp_path):
    """A test carrying one of the suite's marks that its module's text does not name (given
    by a plugin, say) stops the run with a clear error instead of being skipped unseen."""
    import types
    import conftest
    module = tmp_path / 'test_hidden.py'
    module.write_text('def test_a():\n    pass\n')
    item = types.SimpleNamespace(
        path=module, nodeid='test_hidden.py::test_a', add_marker=lambda mark: None,
        get_closest_marker=lambda name: None,
        iter_markers=lambda: iter([pytest.mark.numerical.mark]))
    config = types.SimpleNamespace(getini=lambda name: ['numerical: linear algebra'])
    with pytest.raises(pytest.UsageError, match=r"carries marks \['numerical'\]"):
        conftest.pytest_collection_modifyitems(config, [item])
    item.iter_markers = lambda: iter([pytest.mark.parametrize.mark])     # not one of ours
    conftest.pytest_collection_modifyitems(config, [item])
