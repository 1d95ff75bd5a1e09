"""The flat layout's module paths (``nonfragile_tracker.control.lmi``) still import, for users'
scripts: as the very module of the new path, with a DeprecationWarning naming it.

This module names the old paths on purpose (test_architecture lets it)."""
from __future__ import annotations

import importlib
import subprocess
import sys
import warnings

import pytest

import nonfragile_tracker.control as control
from conftest import ROOT


def _forget(old: str) -> None:
    """Make the next import of ``control.<old>`` go through the finder again."""
    sys.modules.pop(f'nonfragile_tracker.control.{old}', None)
    control.__dict__.pop(old, None)


@pytest.mark.parametrize('old, part', sorted(control.MOVED.items()))
def test_an_old_path_is_the_new_module_with_a_warning(old, part):
    _forget(old)
    new = importlib.import_module(f'nonfragile_tracker.control.{part}.{old}')
    with pytest.warns(DeprecationWarning) as caught:
        aliased = importlib.import_module(f'nonfragile_tracker.control.{old}')
    assert aliased is new
    assert sys.modules[f'nonfragile_tracker.control.{old}'] is new
    assert [str(w.message) for w in caught] == [
        f'nonfragile_tracker.control.{old} is deprecated: the module moved to '
        f'nonfragile_tracker.control.{part}.{old}; import it from there (or its public names '
        f'from nonfragile_tracker.control.{part})']
    assert caught[0].filename == __file__           # the importing line, not importlib's
    # the module keeps its own identity
    assert new.__name__ == new.__spec__.name == f'nonfragile_tracker.control.{part}.{old}'
    assert new.__spec__.origin == new.__file__
    _forget(old)


def test_classes_are_shared_across_the_old_and_new_paths():
    _forget('loop')
    _forget('lmi')
    from nonfragile_tracker.control.simulation.loop import TrackerConfig
    from nonfragile_tracker.control.synthesis.errors import InfeasibleError
    with pytest.warns(DeprecationWarning, match='control.simulation.loop'):
        from nonfragile_tracker.control.loop import LoopConfigError, TrackerConfig as Old
    with pytest.warns(DeprecationWarning, match='control.synthesis.lmi'):
        from nonfragile_tracker.control import lmi
    assert Old is TrackerConfig
    from nonfragile_tracker.control.simulation.gains import read_gain_file
    config = Old(K=read_gain_file(ROOT / 'config' / 'tracker_gains.yaml'))
    assert isinstance(config, TrackerConfig)
    assert lmi.InfeasibleError is InfeasibleError
    from nonfragile_tracker.control.simulation.errors import LoopConfigError as New
    assert LoopConfigError is New
    # imported once: the second time, no warning and the same object
    with warnings.catch_warnings():
        warnings.simplefilter('error')
        import nonfragile_tracker.control.lmi as again
    assert again is lmi


@pytest.mark.parametrize('name', ['nosuch', 'errors', 'synthesis.loop', 'simulation.lmi'])
def test_an_unknown_path_is_still_module_not_found(name):
    with warnings.catch_warnings():
        warnings.simplefilter('error')
        with pytest.raises(ModuleNotFoundError, match=f"No module named "
                                                      f"'nonfragile_tracker.control.{name}'"):
            importlib.import_module(f'nonfragile_tracker.control.{name}')


def test_a_users_script_sees_the_warning_by_default(tmp_path):
    """Python shows a DeprecationWarning by default when the ``__main__`` script triggers it;
    the warning points at the script's import line."""
    script = tmp_path / 'script.py'
    script.write_text('from nonfragile_tracker.control.gains import read_gain_file\n'
                      "print(read_gain_file('config/tracker_gains.yaml').shape)\n")
    proc = subprocess.run([sys.executable, str(script)], cwd=ROOT, capture_output=True,
                          text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == '(2, 4)'
    assert proc.stderr.startswith(
        f'{script}:1: DeprecationWarning: nonfragile_tracker.control.gains is deprecated: the '
        'module moved to nonfragile_tracker.control.simulation.gains'), proc.stderr


def test_the_finder_is_installed_once():
    importlib.reload(control)
    finders = [f for f in sys.meta_path if getattr(f, 'package', None) == control.__name__]
    assert len(finders) == 1
