"""The docs' *Layout* section (doc/developing.md) matches the tree: every path it lists exists,
every folder of the package has an entry whose module list is generated (so a new module
needs no entry), and every root module, configuration file and test directory is listed."""
from __future__ import annotations

import re

import pytest

from conftest import ROOT

PKG = ROOT / 'nonfragile_tracker'


LAYOUT_PAGE = ROOT / 'doc' / 'developing.md'


def _layout_rows() -> list[tuple[list[str], str]]:
    """(paths of an entry's heading, its description) of each ``### `path` `` entry of the
    Layout section."""
    text = LAYOUT_PAGE.read_text()
    section = text.split('\n## Layout\n', 1)[1].split('\n## ', 1)[0]
    rows = []
    for entry in section.split('\n### ')[1:]:
        heading, _, desc = entry.partition('\n')
        rows.append((re.findall(r'`([^`]+)`', heading), desc))
    return rows


def _listed_paths() -> list[str]:
    """The first column's paths; a bare file name after a path is in that path's folder
    (``nonfragile_tracker/workflows/runner.py``, ``reproduce.py``)."""
    out = []
    for paths, _ in _layout_rows():
        folder = ''
        for p in paths:
            if '/' in p.rstrip('/'):
                folder = p.rsplit('/', 1)[0] + '/' if not p.endswith('/') else ''
                out.append(p)
            else:
                out.append(folder + p)
    return out


def _names_in(row_path: str) -> set[str]:
    """Back-quoted words of the description of the row for ``row_path``."""
    for paths, desc in _layout_rows():
        if row_path in paths:
            return set(re.findall(r'`([A-Za-z_][\w]*)`', desc))
    raise AssertionError(f'{LAYOUT_PAGE.name} Layout has no entry for {row_path}')


def test_layout_section_has_rows():
    assert len(_layout_rows()) >= 10


@pytest.mark.parametrize('path', _listed_paths())
def test_every_listed_path_exists(path):
    assert (ROOT / path).exists(), f'{LAYOUT_PAGE.name} Layout lists {path}, which does not exist'


#: Every subpackage, nested ones too (``control/synthesis``), as a path under the package.
SUBPACKAGES = sorted(str(p.parent.relative_to(PKG)) for p in PKG.rglob('__init__.py')
                     if p.parent != PKG)


def test_the_subpackages_are_found():
    assert {'control', 'control/synthesis', 'control/simulation', 'control/identification',
            'nodes', 'bag', 'commands'} <= set(SUBPACKAGES)


@pytest.mark.parametrize('sub', SUBPACKAGES)
def test_every_folder_has_an_entry_with_its_generated_module_list(sub):
    """The list is the ``modules`` directive (doc/_ext: each module's docstring summary)."""
    for paths, desc in _layout_rows():
        if f'nonfragile_tracker/{sub}/' in paths:
            package = 'nonfragile_tracker.' + sub.replace('/', '.')
            assert f'```{{modules}} {package}\n```' in desc, (sub, desc)
            return
    raise AssertionError(f'{LAYOUT_PAGE.name} Layout has no entry for nonfragile_tracker/{sub}/')


def test_every_top_level_module_is_listed():
    listed = set(_listed_paths())
    modules = {f'nonfragile_tracker/{p.name}' for p in PKG.glob('*.py') if p.stem != '__init__'}
    assert not modules - listed, sorted(modules - listed)


def test_every_configuration_file_and_test_directory_is_listed():
    config = {p.name for p in (ROOT / 'config').glob('*.yaml')}
    names = set(re.findall(r'`([\w.]+\.yaml)`', dict(
        (tuple(p), d) for p, d in _layout_rows())[('config/',)]))
    assert not config - names, sorted(config - names)
    tests = {p.name for p in (ROOT / 'test').iterdir()
             if p.is_dir() and not p.name.startswith(('.', '__'))}
    desc = dict((tuple(p), d) for p, d in _layout_rows())[('test/',)]
    assert all(f'`{t}/' in desc for t in tests), (sorted(tests), desc)
