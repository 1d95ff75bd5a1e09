"""The documentation: README.md is short and links only to what exists; the Sphinx + MyST
project in doc/ (rosdoc2's layout) builds with warnings as errors, and its generated parts
(parameter tables, command help, API) cover every node, command and module."""
from __future__ import annotations

import ast
import re
import subprocess
import sys
import xml.etree.ElementTree as ET

import pytest
import yaml

from conftest import ROOT

DOC = ROOT / 'doc'
PKG = ROOT / 'nonfragile_tracker'
sys.path.insert(0, str(DOC / '_ext'))
import nonfragile_docs  # noqa: E402  (doc/_ext, the docs' own extension)


def _readme() -> str:
    return (ROOT / 'README.md').read_text()


def test_readme_is_short_with_narrow_lines():
    lines = _readme().splitlines()
    assert len(lines) <= 200, f'README.md has {len(lines)} lines; move detail into doc/'
    wide = [(i + 1, len(line)) for i, line in enumerate(lines) if len(line) > 120]
    assert not wide, f'README.md lines wider than 120 characters: {wide}'


def test_readme_has_the_sections_a_newcomer_needs():
    headings = re.findall(r'^## (.+)$', _readme(), flags=re.MULTILINE)
    for needed in ('Install', 'Two commands', 'Bring up the tracker on a new robot',
                   'Documentation', 'Limits'):
        assert needed in headings, (needed, headings)
    text = _readme()
    for command in ('make demo', 'make test', 'make docs', 'identify', 'latency-design'):
        assert command in text, command


def test_readme_links_point_to_existing_files():
    links = re.findall(r'\]\(([^)#]+)(?:#[^)]*)?\)', _readme())
    local = [link for link in links if '://' not in link]
    assert len(local) >= 10, local
    missing = [link for link in local if not (ROOT / link).exists()]
    assert not missing, f'README.md links to missing files: {missing}'


def test_rosdoc2_configuration_is_exported_and_names_doc():
    export = ET.parse(ROOT / 'package.xml').getroot().find('export')
    assert export is not None and export.findtext('rosdoc2') == 'rosdoc2.yaml'
    attic, config = yaml.safe_load_all((ROOT / 'rosdoc2.yaml').read_text())
    assert attic == {'type': 'rosdoc2 config', 'version': 1}
    sphinx = [b['sphinx'] for b in config['builders'] if 'sphinx' in b]
    assert sphinx and sphinx[0]['sphinx_sourcedir'] == 'doc'
    assert (DOC / 'conf.py').is_file() and (DOC / 'index.md').is_file()


def test_every_command_has_a_section_with_its_help():
    """Each sub-command of the CLI (``bag report`` for nested ones) has a ``cli-help``
    block in the CLI reference, so a new command cannot go undocumented."""
    text = (DOC / 'cli.md').read_text()
    documented = set(re.findall(r'^```\{cli-help\} (.+)$', text, flags=re.MULTILINE))
    parsers = nonfragile_docs.command_parsers()
    leaves = {name for name in parsers
              if not any(other.startswith(name + ' ') for other in parsers)}
    assert leaves - documented == set(), sorted(leaves - documented)
    assert documented - set(parsers) == set(), sorted(documented - set(parsers))


def test_every_node_has_its_generated_parameter_table():
    text = (DOC / 'ros-interface.md').read_text()
    tables = re.findall(r'^```\{node-parameters\} (\w+)$', text, flags=re.MULTILINE)
    assert sorted(tables) == sorted(nonfragile_docs.NODE_MODULES)
    # the rows are the declarations themselves: same names, in order, same descriptions
    from nonfragile_tracker.nodes import tracker
    rows = nonfragile_docs.parameter_rows('tracker')
    declared = tracker.PARAMS + tracker.MONITOR_PARAMS           # what the node binds
    assert [r[0] for r in rows] == [p.name for p in declared]
    assert [r[5] for r in rows] == [p.description for p in declared]
    assert {'monitor', 'monitor_window', 'monitor_adapt', 'certified_residual',
            'certified_lag'} <= {r[0] for r in rows}
    by_name = {r[0]: r for r in rows}
    # type, default, range, read-only as declared (tracker.PARAMS: dt 0 = from the odometry
    # stamps, low=0, high=10)
    assert by_name['dt'][1:5] == ['double', '0.0', '[0, 10]', 'yes']
    assert by_name['K'][1:3] == ['double[]', '(none: from a file or -p)']
    assert by_name['K_shape'][1:5] == ['integer[]', '[2, 4]', '', 'yes']


def test_every_launch_file_has_its_generated_argument_table():
    text = (DOC / 'ros-interface.md').read_text()
    tables = re.findall(r'^```\{launch-arguments\} (\S+)$', text, flags=re.MULTILINE)
    assert sorted(tables) == sorted(p.name for p in (ROOT / 'launch').glob('*.launch.py'))
    rows = {r[0]: r for r in nonfragile_docs.launch_argument_rows(
        ROOT / 'launch' / 'robot.launch.py')}
    assert rows['gains'][1] == '<share>/config/tracker_gains.yaml'
    assert rows['use_sim_time'][1:3] == ['false', 'true, false']
    assert rows['namespace'][1] == '(empty)'


@pytest.mark.parametrize('module, section', [
    ('lmi', 'theorem-1'), ('delay_dependent', 'delay-dependent-design'),
    ('input_delay', 'input-delay-command-latency'), ('predictor', 'latency-predictor'),
    ('monitor', 'latency-monitor'), ('limits', 'topp-ra')])
def test_derivations_live_in_theory_and_docstrings_point_there(module, section):
    sub = {'predictor': 'simulation', 'limits': 'simulation',
           'monitor': 'identification'}.get(module, 'synthesis')
    doc = ast.get_docstring(ast.parse((PKG / 'control' / sub / f'{module}.py').read_text()))
    assert doc is not None
    assert 'doc/theory.md' in doc and section in doc, doc
    assert len(doc.splitlines()) <= 20, f'{module} docstring: keep a summary, derive in theory'
    theory = (DOC / 'theory.md').read_text()
    assert f'nonfragile_tracker.control.{sub}.{module}' in theory


def _sphinx(out, *options: str) -> subprocess.CompletedProcess:
    """``sphinx-build -W --keep-going -q -b html doc OUT`` (any warning fails the build)."""
    return subprocess.run([sys.executable, '-m', 'sphinx', '-W', '--keep-going', '-q', '-b',
                           'html', '-d', str(out / '.doctrees'), *options, str(DOC), str(out)],
                          cwd=ROOT, capture_output=True, text=True, timeout=300)


#: What rosdoc2 (0.2) puts around a package's doc/conf.py: its own conf.py in a build folder
#: exec's ours (so ``__file__`` is not doc/conf.py), then adds its extensions and theme.
ROSDOC2_WRAPPER = """\
import os
import sys
exec(open({conf!r}).read())
extensions.append('sphinx.ext.autodoc')
extensions.append('sphinx.ext.intersphinx')
extensions.append('sphinx_rtd_theme')
html_theme = 'sphinx_rtd_theme'
extensions.append('myst_parser')
"""


@pytest.fixture(scope='module')
def site(tmp_path_factory):
    """The whole site with the API reference (autodoc + napoleon over every module; about
    15 s of CPU, once for the module's tests), built the way rosdoc2 builds it (``-c`` a
    wrapping conf.py that exec's ours), warnings as errors."""
    tmp = tmp_path_factory.mktemp('docs')
    wrapper = tmp / 'rosdoc2_wrapper'
    wrapper.mkdir()
    (wrapper / 'conf.py').write_text(ROSDOC2_WRAPPER.format(conf=str(DOC / 'conf.py')))
    out = tmp / 'html'
    proc = _sphinx(out, '-c', str(wrapper))
    return out, proc


@pytest.mark.slow
def test_full_docs_build_without_warnings(site):
    """Docstring markup that breaks fails, and every module has its entry."""
    out, proc = site
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert proc.stderr.strip() == '', proc.stderr
    api = ''.join(p.read_text() for p in (out / 'api').glob('*.html'))
    modules = {'nonfragile_tracker.' + p.relative_to(PKG).with_suffix('').as_posix()
               .replace('/', '.') for p in PKG.rglob('*.py') if p.stem != '__init__'}
    missing = {m for m in modules if f'id="module-{m}"' not in api}
    assert not missing, sorted(missing)
    assert len(modules) >= 60


@pytest.mark.slow
def test_the_layout_lists_every_module_with_its_summary(site):
    """developing.md's Layout is generated per folder (``modules``): every module of the
    package is there, with its docstring's first line."""
    import ast
    out, _ = site
    html = (out / 'developing.html').read_text()
    import html as _html
    text = _html.unescape(re.sub(r'<[^>]+>', '', html))
    for smart, plain in (('\u2019', "'"), ('\u2018', "'"), ('\u201c', '"'), ('\u201d', '"')):
        text = text.replace(smart, plain)
    missing = []
    for path in sorted(PKG.rglob('*.py')):
        if path.stem == '__init__' or path.parent == PKG:
            continue
        summary = (ast.get_docstring(ast.parse(path.read_text())) or '').splitlines()[0]
        words = re.sub(r':[\w:]+:`~?([^`<]+?)(?: <[^>]+>)?`', r'\1', summary)
        words = words.replace('``', '').replace('`', '').split()[:4]
        if f'{path.stem}: ' + ' '.join(words) not in ' '.join(text.split()):
            missing.append(f'{path.relative_to(PKG)}: {" ".join(words)}')
    assert not missing, missing


@pytest.mark.slow
def test_pages_build_without_warnings(site):
    """The narrative pages of the same build: a broken link, a missing anchor or bad
    markup is a warning, and a warning fails; the generated tables are in them."""
    out, proc = site
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert proc.stderr.strip() == '', proc.stderr
    for page in ('index', 'getting-started', 'tutorial', 'cli', 'ros-interface', 'bags',
                 'study', 'safety', 'theory', 'developing', 'reproduction/paper_reproduction',
                 'limits', 'troubleshooting'):
        assert (out / f'{page}.html').is_file(), page
    ros = (out / 'ros-interface.html').read_text()
    # generated tables: one row per declaration of every node
    for name in ('predict_latency', 'lockstep_lead', 'chunk_size', 'display_points',
                 'monitor_window', 'certified_residual'):
        assert f'<code class="docutils literal notranslate"><span class="pre">{name}' in ros
    cli = (out / 'cli.html').read_text()
    assert cli.count('usage: nonfragile_tracker') == len(re.findall(
        r'^```\{cli-help\}', (DOC / 'cli.md').read_text(), flags=re.MULTILINE))
    assert '(reproduction.html' not in ros and (out / '_images').is_dir()


def _github_slug(heading: str) -> str:
    """GitHub's anchor of a Markdown heading (lower case, punctuation dropped, - for space)."""
    text = re.sub(r'[^\w\- ]', '', heading.strip().lower().replace('`', ''))
    return text.replace(' ', '-')


def test_links_between_pages_work_on_github_too():
    """A link ``page.md#anchor`` must name a heading of that page by GitHub's rule, not only
    a Sphinx label (``(label)=``) that GitHub does not know; relative .md paths only."""
    pages = [ROOT / 'README.md', *sorted(DOC.rglob('*.md'))]
    anchors = {}
    for page in pages:
        seen: dict[str, int] = {}
        text = re.sub(r'^```.*?^```', '', page.read_text(), flags=re.MULTILINE | re.DOTALL)
        for heading in re.findall(r'^#{1,6} (.+)$', text, flags=re.MULTILINE):
            slug = _github_slug(heading)
            anchors.setdefault(page, set()).add(slug if slug not in seen else
                                                f'{slug}-{seen[slug]}')
            seen[slug] = seen.get(slug, 0) + 1
    bad = []
    for page in pages:
        for path, anchor in re.findall(r'\]\(([^)\s#]*)#([^)\s]+)\)', page.read_text()):
            target = (page.parent / path).resolve() if path else page
            if target.suffix == '.md' and anchor not in anchors.get(target, set()):
                bad.append(f'{page.relative_to(ROOT)}: {path}#{anchor}')
    assert not bad, bad
