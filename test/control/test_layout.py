"""The control core's three parts: each re-exports its public names lazily, and the
simulation (what the nodes import) never loads the synthesis or cvxpy."""
from __future__ import annotations

import ast
import importlib
import subprocess
import sys

import pytest

from conftest import ROOT

PARTS = ('synthesis', 'simulation', 'identification')


def _run(code: str) -> str:
    """Run ``code`` in a fresh interpreter (nothing imported yet) and return its stdout."""
    proc = subprocess.run([sys.executable, '-c', code], cwd=ROOT, capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return proc.stdout


def test_the_simulation_runs_without_the_synthesis_or_cvxpy():
    """Every public name of the simulation and a tracking run of the shipped gain (the nodes'
    step functions), plus the tracker node's monitor: no synthesis module, no cvxpy."""
    out = _run(
        'import sys\n'
        'from nonfragile_tracker.control.simulation import *\n'
        'from nonfragile_tracker.control.identification import monitor\n'
        "K = read_gain_file('config/tracker_gains.yaml')\n"
        'run = simulate_tracking(PlantConfig(), TrackerConfig(K=K), circle(), 500)\n'
        'print(run.error.shape[0])\n'
        "print(sorted(m for m in sys.modules if m == 'cvxpy' or '.synthesis' in m))\n")
    assert out.split('\n')[:2] == ['501', '[]'], out


@pytest.mark.parametrize('part', PARTS)
def test_importing_a_part_imports_none_of_its_modules(part):
    out = _run(f'import sys\nimport nonfragile_tracker.control.{part}\n'
               "print(sorted(m for m in sys.modules if m.startswith('nonfragile_tracker')))\n")
    assert out.strip() == str(['nonfragile_tracker', 'nonfragile_tracker.control',
                               f'nonfragile_tracker.control.{part}'])


def _exports(part: str) -> dict[str, str]:
    """name -> defining module, from the ``if TYPE_CHECKING:`` imports of the part's
    ``__init__.py`` (what type checkers see)."""
    tree = ast.parse((ROOT / 'nonfragile_tracker' / 'control' / part / '__init__.py')
                     .read_text())
    return {alias.name: node.module for block in tree.body if isinstance(block, ast.If)
            for node in block.body if isinstance(node, ast.ImportFrom)
            for alias in node.names}


@pytest.mark.parametrize('part', PARTS)
def test_every_exported_name_is_the_object_of_its_module(part):
    package = importlib.import_module(f'nonfragile_tracker.control.{part}')
    exports = _exports(part)
    assert sorted(package.__all__) == sorted(exports)
    assert len(package.__all__) == len(set(package.__all__))
    for name, module in exports.items():
        defining = importlib.import_module(f'nonfragile_tracker.control.{part}.{module}')
        assert getattr(package, name) is getattr(defining, name), name
    assert set(package.__all__) <= set(dir(package))
    # no exported name hides a module of the part (the import system would overwrite it)
    modules = {p.stem for p in (ROOT / 'nonfragile_tracker' / 'control' / part).glob('*.py')}
    assert not modules & set(exports)


def test_a_name_not_exported_is_an_attribute_error():
    from nonfragile_tracker.control import simulation
    with pytest.raises(AttributeError, match="'nonfragile_tracker.control.simulation' has no "
                                             "attribute 'synthesize'"):
        getattr(simulation, 'synthesize')
    with pytest.raises(ImportError, match='synthesize'):
        exec('from nonfragile_tracker.control.simulation import synthesize', {})


def test_the_public_names_users_import_are_exported():
    """The names of the README's and the docs' examples, at their parts."""
    from nonfragile_tracker.control import identification, simulation, synthesis
    assert {'load_problem', 'synthesize', 'certify_gain', 'design_for_latency', 'analyse_gain',
            'InfeasibleError', 'ProblemError'} <= set(synthesis.__all__)
    assert {'Tracker', 'TrackerConfig', 'PlantConfig', 'simulate_tracking', 'read_gain_file',
            'Trajectory', 'load_waypoints', 'simulate_batch', 'run_study'} <= set(simulation.__all__)
    assert {'identify_latency', 'read_identification', 'MonitorWorker', 'record_tracking',
            'IdentificationError'} <= set(identification.__all__)
