"""Shared fixtures: paths to the shipped configuration and the paper's data."""
from __future__ import annotations

import contextlib
import fcntl
import functools
import io
import itertools
import os
import pickle
import re
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

# a node that did not end: its stacks into its log, then killed (the runner's helper)
from nonfragile_tracker.workflows.runner import kill_with_stacks  # noqa: F401

ROOT = Path(__file__).resolve().parent.parent
CONFIG = ROOT / 'config'
#: Golden bags and the gain they pin (``test/data``).
DATA = ROOT / 'test' / 'data'
#: Every test module under it starts nodes or an rclpy context (all marked ``ros``).
_NODES_DIR = ROOT / 'test' / 'nodes'

# Tests keep DDS discovery on this host, whatever the caller's environment says.
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'

#: Test modules (by file name, wherever they are under test/) that start nodes or an rclpy
#: context: every test in them is marked ``ros`` (markers are registered in setup.cfg;
#: ``pytest -m "not ros"`` runs the ROS-free suite).  Other modules mark their ROS tests
#: with ``@pytest.mark.ros`` / ``pytestmark``.
ROS_MODULES = {'test_bag_writer_reader', 'test_failures', 'test_golden_regression',
               'test_node_parameters', 'test_realtime_faults', 'test_recorder_node',
               'test_ros_lockstep', 'test_tracker_safety'}
#: Modules whose tests run nodes on the wall clock and judge timing or quality (marked
#: ``realtime`` and ``ros``): they run one after another with the machine to themselves.
#: Other tests mark theirs with ``@pytest.mark.realtime``.
REALTIME_MODULES = {'test_bag_realtime', 'test_netns', 'test_realtime_faults',
                    'test_certificate_monitor'}
#: Modules that keep a worker busy longest (tens of seconds each, measured): collected
#: first, so that pytest-xdist (whole modules per worker, handed out in collection order:
#: :func:`pytest_cmdline_main` turns its reordering by number of tests off)
#: starts them first instead of leaving one running alone at the end of a pass.  The
#: real-time modules are in the order that pairs them evenly on three workers.
LONGEST_FIRST = ('test_signals', 'test_failures', 'test_docs', 'test_reproduction',
                 'test_identify', 'test_recorder_node', 'test_input_delay',
                 'test_colcon_setuptools', 'test_bag_golden_user', 'test_golden_regression',
                 'test_latency_lockstep', 'test_realtime_faults',
                 'test_trajectory_realtime_replay', 'test_trajectory_nodes', 'test_netns',
                 'test_bringup_node', 'test_bag_realtime')
#: Modules whose tests take tens of seconds (marked ``slow``).
SLOW_MODULES = {'test_reproduction', 'test_golden_regression', 'test_realtime_faults',
                'test_ros_lockstep'}


def serial_run(expr: str) -> bool:
    """Whether a run with mark expression ``expr`` must be serial: it may select real-time
    tests together with others (``-m realtime`` alone may use workers, see
    :func:`pytest_cmdline_main`)."""
    return (mark_expression_may_select(expr, 'realtime', 'ros')
            and _may_match(expr, frozenset(), frozenset({'realtime'})))


def ros_may_run(config) -> bool:
    """Whether the ``-m`` mark expression may select a test marked ``ros``.

    True unless the expression is false for ``ros`` whatever the other marks it names
    (``slow``, ...) are: ``-m "not ros"`` and ``-m "not ros and not slow"`` exclude ROS
    tests, ``-m "not ros or slow"`` does not.  An expression pytest cannot parse counts as
    selecting them (pytest itself then reports the error).
    """
    return mark_expression_may_select(config.getoption('markexpr') or '', 'ros')


def mark_expression_may_select(expr: str, mark: str, *implied: str) -> bool:
    """Whether ``-m expr`` is true for some test carrying ``mark`` and the ``implied`` marks
    (every combination of the other names in ``expr``, present or absent, is tried)."""
    return _may_match(expr, frozenset({mark, *implied}), frozenset())


@functools.lru_cache(maxsize=None)      # asked for every collected path: parse once
def _may_match(expr: str, present: frozenset[str], absent: frozenset[str]) -> bool:
    """Whether ``-m expr`` is true for some test with the ``present`` marks and without the
    ``absent`` ones, whatever the other names in ``expr``; an empty expression, or one pytest
    cannot parse (it reports the error itself), matches."""
    if not expr.strip():
        return True
    from _pytest.mark.expression import Expression     # pytest's own -m parser
    try:
        compiled = Expression.compile(expr)
    except SyntaxError:
        return True
    fixed = {**dict.fromkeys(present, True), **dict.fromkeys(absent, False)}
    names = sorted(set(re.findall(r'[A-Za-z_][\w.\-]*', expr)) - {'and', 'or', 'not'} - set(fixed))
    for bits in itertools.product((False, True), repeat=len(names)):
        marks = dict(zip(names, bits), **fixed)
        if compiled.evaluate(lambda name, **kwargs: marks.get(name, False)):
            return True
    return False


@pytest.hookimpl(tryfirst=True)        # before pytest-xdist reads the number of workers
def pytest_cmdline_main(config):
    """Serial run (as ``-n 0``) whenever real-time tests may run together with others.

    pytest-xdist runs the tests on every core (``-n auto --dist loadfile`` in setup.cfg, whole
    modules per worker so that module fixtures are computed once), ROS tests in lockstep or
    about processes and signals included: their results do not depend on the load (each
    worker has ROS domains of its own, :func:`domain_ids`).  Real-time tests (``realtime``)
    keep wall-clock time: they must not share the machine with the CPU-bound tests.  Alone
    (``-m realtime``, ``make test`` runs them with ``-n 3``) three of them may run at once:
    together they keep about 0.75 of the two cores busy (nodes at 100 Hz and waits).
    (xdist's ``loadgroup`` cannot keep them together: with pytest 9.2 its group marks have no
    effect, pytest-xdist issue 1386.)
    """
    if serial_run(config.getoption('markexpr') or '') \
            and getattr(config.option, 'numprocesses', None):
        config.option.numprocesses = 0
    if hasattr(config.option, 'loadscopereorder'):
        # modules in the collection order (LONGEST_FIRST), not by their number of tests
        # (``--no-loadscope-reorder``, pytest-xdist >= 3.8; older ones always reorder)
        config.option.loadscopereorder = False


def pytest_ignore_collect(collection_path, config):
    """A module none of whose tests the ``-m`` expression can select is not even imported
    (each worker of each ``make test`` pass would import and collect every module: ~4 s of
    CPU; the real-time and second-kernel passes select a few modules): the marks its tests
    may carry are the ones this file gives them (:func:`pytest_collection_modifyitems`) and
    those its text names (``mark.<name>``).  ``None`` leaves the decision to pytest."""
    if collection_path.suffix != '.py' or not collection_path.name.startswith('test_'):
        return None
    expr = config.getoption('markexpr') or ''
    if not expr.strip():
        return None
    given, named = _module_marks(collection_path)
    absent = frozenset(re.findall(r'[A-Za-z_][\w.\-]*', expr)) - given - named
    return None if _may_match(expr, given, absent) else True


@functools.lru_cache(maxsize=None)
def _module_marks(module_path: Path) -> tuple[frozenset[str], frozenset[str]]:
    """(marks every test of the module gets here, marks its source names)."""
    given = set()
    if module_path.stem in REALTIME_MODULES:
        given |= {'realtime', 'ros'}
    if _ros_only(module_path):
        given.add('ros')
    if module_path.stem in SLOW_MODULES:
        given.add('slow')
    named = set(re.findall(r'mark\.(\w+)', module_path.read_text()))
    if 'realtime' in named:
        named.add('ros')                   # a real-time test is a ROS test too (below)
    return frozenset(given), frozenset(named - given)


def _ros_only(module_path: Path) -> bool:
    """Whether every test of the module is a ROS test (under test/nodes/ or in ROS_MODULES)."""
    return module_path.stem in ROS_MODULES or _NODES_DIR in module_path.resolve().parents


def pytest_report_header(config):
    if serial_run(config.getoption('markexpr') or '') \
            and getattr(config.option, 'numprocesses', None) == 0:
        return 'real-time tests may run: one test after another (pytest-xdist off)'
    return None


def pytest_collection_modifyitems(config, items):
    """Mark ``ros`` every test under ``test/nodes/`` and of :data:`ROS_MODULES`, ``realtime``
    those of :data:`REALTIME_MODULES` (a real-time test is a ROS test too); ``slow`` those
    of :data:`SLOW_MODULES`."""
    rank = {name: i for i, name in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.stem, len(rank)))     # stable
    ours = {line.split(':')[0].strip() for line in config.getini('markers')}
    for item in items:
        if item.path.stem in REALTIME_MODULES:
            item.add_marker(pytest.mark.realtime)
        if _ros_only(item.path) or item.get_closest_marker('realtime'):
            item.add_marker(pytest.mark.ros)
        if item.path.stem in SLOW_MODULES:
            item.add_marker(pytest.mark.slow)
        # what pytest_ignore_collect judged the module by must hold for every test in it
        given, named = _module_marks(item.path)
        extra = {m.name for m in item.iter_markers()} & ours - given - named
        if extra:
            raise pytest.UsageError(
                f'{item.nodeid} carries marks {sorted(extra)} that neither its module\'s text '
                'nor test/conftest.py names: a -m run could skip its module; name the mark '
                'in the module (e.g. pytestmark) or list the module in conftest')


def _domain_range() -> range:
    """The ROS_DOMAIN_IDs this test process may use: 100..199, split evenly between the
    pytest-xdist workers (a worker runs its tests one after another)."""
    worker = os.environ.get('PYTEST_XDIST_WORKER', '')
    count = max(int(os.environ.get('PYTEST_XDIST_WORKER_COUNT', '1')), 1)
    index = int(worker[2:]) if worker.startswith('gw') else 0
    size = 100 // count
    return range(100 + index * size, 100 + (index + 1) * size)


def domain_ids(salt: str = '', n: int = 1) -> list[int]:
    """``n`` distinct ROS_DOMAIN_IDs of this process's range, from the process id and a salt."""
    ids = _domain_range()
    assert n <= len(ids), f'{n} domains wanted, {len(ids)} in this worker\'s range'
    first = (os.getpid() * 31 + sum(map(ord, salt))) % len(ids)
    return [ids[(first + k) % len(ids)] for k in range(n)]


def unique_domain_id(salt: str = '') -> int:
    """A ROS_DOMAIN_ID of this process's range (:func:`domain_ids`)."""
    return domain_ids(salt)[0]


if os.environ.get('PYTEST_XDIST_WORKER'):
    # nodes started without a domain of their test's (runner.isolated_env keeps a set one)
    os.environ['ROS_DOMAIN_ID'] = str(unique_domain_id('worker'))


@pytest.fixture(scope='session')
def paper_problem():
    from nonfragile_tracker.control.synthesis.problem import load_problem
    return load_problem(CONFIG / 'paper_problem.yaml')


@pytest.fixture(scope='session')
def paper_gains():
    import yaml
    data = yaml.safe_load((CONFIG / 'paper_gains.yaml').read_text())
    return {k: np.array(v, dtype=float) for k, v in data.items()}


#: A double integrator with a small perturbation: a problem file for fast latency designs.
DI_PROBLEM = """
name: di
A: [[0.0, 1.0], [0.0, 0.0]]
B: [[0.0], [1.0]]
A_tau: [[0.0, 0.0], [0.0, 0.0]]
tau: 0.1
E: [[1.0]]
F: [[0.2, 0.2]]
perturbations: {minus: [[-1.0]], plus: [[1.0]]}
options: {gain_bound: 3.0}
"""


def mapped(pid: int, marker: str) -> bool:
    """Whether a shared object whose path holds ``marker`` is mapped into process ``pid``
    (a defined moment of a process's start-up, e.g. numpy's extension loaded)."""
    try:
        with open(f'/proc/{pid}/maps') as fh:
            return marker in fh.read()
    except OSError:
        return False


#: The gain budget of the shipped gain (``options.gain_bound`` of ``config/paper_problem.yaml``).
SHIPPED_NORM = 8.67
#: The command that regenerates ``config/max_decay_gains.yaml`` (the max-decay design: ideal
#: plants, lockstep; doc/getting-started.md "The shipped gain").
SHIPPED_DESIGN_ARGV = ['design', str(CONFIG / 'paper_problem.yaml'), '--objective', 'decay',
                       '--norm', str(SHIPPED_NORM)]


def _design_shipped_gain(path: Path) -> SimpleNamespace:
    """``design ... -o path`` through ``cli.main`` with a spy on ``design.at_gain_norm``."""
    from nonfragile_tracker.cli import main
    from nonfragile_tracker.control.synthesis import design

    real, calls = design.at_gain_norm, []

    def spy(*args, **kwargs):
        res = real(*args, **kwargs)
        calls.append((args, kwargs, res))
        return res

    out = io.StringIO()
    patch = pytest.MonkeyPatch()
    patch.setattr(design, 'at_gain_norm', spy)
    try:
        with contextlib.redirect_stdout(out):
            code = main(SHIPPED_DESIGN_ARGV + ['-o', str(path)])
    finally:
        patch.undo()
    return SimpleNamespace(code=code, path=path, stdout=out.getvalue(), calls=calls)


@pytest.fixture(scope='session')
def shipped_design(request, tmp_path_factory):
    """The max-decay gain's command run once per test run (its max-decay design costs seconds).

    ``design config/paper_problem.yaml --objective decay --norm 8.67 -o FILE`` through
    ``cli.main``, with a pass-through spy on ``control.synthesis.design.at_gain_norm`` that records
    each call and its :class:`DesignResult`.  Returns a namespace with ``code`` (exit
    code), ``path`` (the gain file), ``stdout`` and ``calls`` (``(args, kwargs, result)``).
    Shared by the CLI test, the shipped-gain test and the design tests (same computation);
    under pytest-xdist the first worker to need it computes it and the others read its
    pickle (the run's shared temporary directory, a file lock between them).
    """
    if not hasattr(request.config, 'workerinput'):           # one process: no sharing
        return _design_shipped_gain(tmp_path_factory.mktemp('shipped_design') / 'gains.yaml')
    shared = tmp_path_factory.getbasetemp().parent           # this run's, all workers'
    name = f'shipped_design_{request.config.workerinput["testrunuid"]}'   # and this run's only
    with open(shared / f'{name}.lock', 'w') as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        done = shared / f'{name}.pickle'
        if done.is_file():
            return pickle.loads(done.read_bytes())
        res = _design_shipped_gain(shared / f'{name}.yaml')
        part = done.with_suffix('.part')
        part.write_bytes(pickle.dumps(res))
        os.replace(part, done)                                # whole, or not there
        return res


@pytest.fixture
def ros_env(tmp_path):
    """Environment for ROS subprocesses: an isolated domain on localhost."""
    env = dict(os.environ)
    env['ROS_DOMAIN_ID'] = str(unique_domain_id(tmp_path.name))
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    env['PYTHONPATH'] = str(ROOT) + os.pathsep + env.get('PYTHONPATH', '')
    return env

