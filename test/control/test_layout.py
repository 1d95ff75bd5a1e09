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
            'Trajectory', 'load_waypoints', 'simulate_batch',
            'run_study'} <= set(simulation.__all__)
    assert {'identify_latency', 'read_identification', 'MonitorWorker', 'record_tracking',
            'IdentificationError'} <= set(identification.__all__)


#: Each part's errors: class -> (builtin it derives from, exit code, modules that import it
#: for their own use and so keep it importable from there, as before the move).
ERRORS = {
    'synthesis': {'ProblemError': (ValueError, 2, ['problem']),
                  'LmiError': (RuntimeError, 4, ['lmi', 'design', 'sweep']),
                  'InfeasibleError': (RuntimeError, 3, ['lmi', 'design', 'delay_dependent',
                                                        'input_delay', 'latency_design']),
                  'SolverFailure': (RuntimeError, 4, ['lmi', 'sdp']),
                  'CertificateError': (RuntimeError, 4, ['lmi', 'delay_dependent'])},
    'simulation': {'SingularSpeedError': (ValueError, 2, ['model']),
                   'PathError': (ValueError, 2, ['reference']),
                   'TrajectoryError': (ValueError, 2, ['trajectory', 'limits']),
                   'LoopConfigError': (ValueError, 2, ['loop', 'gains']),
                   'GainFileError': (ValueError, 2, ['gains']),
                   'BatchError': (ValueError, 2, ['batch', 'study'])},
    'identification': {'IdentificationError': (ValueError, 2, ['identify']),
                       'NotEnoughDataError': (ValueError, 2, ['identify']),
                       'InsufficientExcitationError': (ValueError, 2, ['identify']),
                       'PoorFitError': (ValueError, 2, ['identify']),
                       'IdentificationFileError': (ValueError, 2, ['identify']),
                       'MonitorError': (ValueError, 2, ['monitor'])},
}


@pytest.mark.parametrize('part', PARTS)
def test_each_part_has_its_errors_under_the_root_error(part):
    from nonfragile_tracker.errors import NonfragileError, exit_code
    errors = importlib.import_module(f'nonfragile_tracker.control.{part}.errors')
    package = importlib.import_module(f'nonfragile_tracker.control.{part}')
    assert sorted(errors.__all__) == sorted(ERRORS[part])
    for name, (builtin, code, modules) in ERRORS[part].items():
        cls = getattr(errors, name)
        assert cls.__module__ == errors.__name__
        assert issubclass(cls, NonfragileError) and issubclass(cls, builtin), name
        assert exit_code(cls('message')) == code, name
        assert getattr(package, name) is cls
        for module in modules:
            where = importlib.import_module(f'nonfragile_tracker.control.{part}.{module}')
            assert getattr(where, name) is cls, (module, name)


def test_the_subclass_order_of_the_errors():
    from nonfragile_tracker.control.identification.errors import (IdentificationError,
                                                                  PoorFitError)
    from nonfragile_tracker.control.simulation.errors import GainFileError, LoopConfigError
    from nonfragile_tracker.control.synthesis.errors import (CertificateError, InfeasibleError,
                                                             LmiError, SolverFailure)
    assert all(issubclass(c, LmiError) for c in (InfeasibleError, SolverFailure,
                                                 CertificateError))
    assert issubclass(GainFileError, LoopConfigError)
    assert issubclass(PoorFitError, IdentificationError)


def test_the_root_errors_name_the_new_home_of_the_lmi_errors():
    """errors.py is the package's foundation and may not import the control core: asking it
    for a moved class says where the class is now."""
    import nonfragile_tracker.errors as errors
    for name in ('LmiError', 'InfeasibleError', 'SolverFailure', 'CertificateError'):
        with pytest.raises(ImportError, match=f'{name} moved to '
                                              r'nonfragile_tracker\.control\.synthesis\.errors'):
            exec(f'from nonfragile_tracker.errors import {name}', {})
        assert name not in errors.__all__
    with pytest.raises(AttributeError, match='no attribute'):
        getattr(errors, 'NoSuchError')
    assert not hasattr(errors, 'NoSuchError')
