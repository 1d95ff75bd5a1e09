"""Package structure: a table of layers checked from the source, CLI layering, no import
cycles, no private name across modules."""
from __future__ import annotations

import ast
import functools
import re
from pathlib import Path

import pytest

PKG = Path(__file__).resolve().parent.parent / 'nonfragile_tracker'


def _module_name(path: Path) -> str:
    rel = path.relative_to(PKG.parent).with_suffix('')
    parts = list(rel.parts)
    if parts[-1] == '__init__':
        parts.pop()
    return '.'.join(parts)


MODULES = {_module_name(p): p for p in sorted(PKG.rglob('*.py'))}


@functools.cache
def _import_nodes(path: Path, source: str | None, top_level_only: bool) -> tuple[ast.stmt, ...]:
    """The import statements of ``path`` (or of ``source``): parsed once per module and
    test process, as each check walks every module."""
    tree = ast.parse(path.read_text() if source is None else source)
    if top_level_only:
        # the module's own imports, with those for type checkers (``if TYPE_CHECKING:``):
        # a cycle that only mypy sees is still two modules that need each other
        nodes = list(tree.body)
        for n in tree.body:
            if isinstance(n, ast.If) and 'TYPE_CHECKING' in ast.unparse(n.test):
                nodes.extend(n.body)
    else:
        nodes = list(ast.walk(tree))
    return tuple(n for n in nodes if isinstance(n, (ast.Import, ast.ImportFrom)))


def _imports(name: str, path: Path, top_level_only: bool, source: str | None = None):
    """(imported module, imported names, line) of ``path``, package-internal only."""
    package = name if path.name == '__init__.py' else name.rpartition('.')[0]
    nodes = _import_nodes(path, source, top_level_only)
    for node in nodes:
        if isinstance(node, ast.ImportFrom) and node.module != '__future__':
            if node.level:
                base = package.split('.')
                base = base[:len(base) - node.level + 1]
                mod = '.'.join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ''
            if not mod.startswith('nonfragile_tracker'):
                continue
            for alias in node.names:
                sub = f'{mod}.{alias.name}'
                yield (sub if sub in MODULES else mod), alias.name, node.lineno
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.startswith('nonfragile_tracker'):
                    yield alias.name, None, node.lineno


def _external_imports(path: Path, source: str | None = None):
    """(top-level package, line) of every import of ``path`` outside the package."""
    for node in _import_nodes(path, source, False):
        if isinstance(node, ast.ImportFrom) and not node.level and node.module:
            names = [node.module]
        elif isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        else:
            continue
        for full in names:
            if not full.startswith('nonfragile_tracker') and full != '__future__':
                yield full.split('.')[0], node.lineno


#: The layers, lowest first: a module imports modules of its own layer or lower ones only.
#: A layer is a folder of the package (a new module in a folder needs no entry here); the
#: few modules at the package's root are named ('' = the package): a new module belongs in
#: a folder, and one loose at the root fails :func:`test_every_module_has_a_layer`.
LAYERS = (
    ('foundation', {'', 'errors', 'files', 'parallel'}),
    ('control', {'control'}),
    ('interface', {'interface'}),
    ('bag', {'bag'}),
    ('nodes', {'nodes'}),
    ('workflows', {'workflows'}),
    ('top', {'commands', 'cli'}),
)
#: The ROS client library and the message packages of the ROS 2 wheels.
ROS = {'rclpy', 'rosidl_runtime_py', 'builtin_interfaces', 'geometry_msgs', 'nav_msgs',
       'std_msgs', 'rosgraph_msgs', 'trajectory_msgs', 'visualization_msgs', 'diagnostic_msgs',
       'sensor_msgs', 'lifecycle_msgs', 'std_srvs', 'rcl_interfaces'}
#: Bag libraries.
BAGS = {'rosbags', 'mcap', 'mcap_ros2'}
#: Third-party packages a layer must not import, wherever in a module (lazy imports too).
FORBIDDEN = {'foundation': ROS | BAGS, 'control': ROS | BAGS, 'interface': ROS | BAGS,
             'bag': ROS}


def layer_of(name: str) -> int:
    """Index in :data:`LAYERS` of module ``name`` (KeyError when no layer lists it)."""
    parts = name.split('.')[1:]
    unit = parts[0] if parts else ''
    for index, (_, units) in enumerate(LAYERS):
        if unit in units:
            return index
    raise KeyError(f'{name} is in no layer of LAYERS: add it where it belongs')


def layer_violations(sources: dict[str, str] | None = None) -> list[str]:
    """Every import that breaks the layer table, as readable lines.

    ``sources`` replaces the text of the named modules (the probe tests plant an import).
    """
    sources = sources or {}
    bad = []
    for name, path in MODULES.items():
        source = sources.get(name)
        layer = layer_of(name)
        for mod, _, line in _imports(name, path, False, source):
            target = mod if mod in MODULES else mod.rpartition('.')[0]
            if target in MODULES and layer_of(target) > layer:
                bad.append(f'{name}:{line} imports {mod} ({LAYERS[layer_of(target)][0]}, above '
                           f'{LAYERS[layer][0]})')
        forbidden = FORBIDDEN.get(LAYERS[layer][0], set())
        for package, line in _external_imports(path, source):
            if package in forbidden:
                bad.append(f'{name}:{line} imports {package} (not allowed in '
                           f'{LAYERS[layer][0]})')
    return bad


def test_every_module_has_a_layer():
    assert all(layer_of(name) >= 0 for name in MODULES)


def test_layers_hold():
    assert layer_violations() == []


@pytest.mark.parametrize('module, line, words', [
    ('nonfragile_tracker.control.simulation.model', 'import rclpy',
     'imports rclpy (not allowed in control)'),
    ('nonfragile_tracker.control.simulation.model', 'from ...bag import reader',
     'imports nonfragile_tracker.bag.reader (bag, above control)'),
    ('nonfragile_tracker.bag.motion', 'from rclpy.node import Node', 'imports rclpy'),
    ('nonfragile_tracker.bag.report', 'from ..workflows import runner',
     'nonfragile_tracker.workflows.runner'),
    ('nonfragile_tracker.nodes.tracker', 'from ..workflows.runner import merge',
     '(workflows, above nodes)'),
    ('nonfragile_tracker.control.simulation.tracker', 'def f():\n    import rosbags',
     'imports rosbags'),
])
def test_the_layer_check_fails_on_a_planted_import(module, line, words):
    source = MODULES[module].read_text() + '\n' + line + '\n'
    bad = layer_violations({module: source})
    assert len(bad) == 1 and words in bad[0], bad


#: The control core's parts and the parts each may import.  What lies at control's root
#: (``validate``, the package ``__init__``) is shared by the three and imports none of them.
CONTROL_PARTS = {
    'simulation': set(),                  # the step functions the nodes run: numpy, no cvxpy
    'identification': {'simulation'},     # a recording drives the simulated loop
    'synthesis': {'identification'},      # a latency design starts from an identification
}


def control_part(name: str) -> str | None:
    """The part of ``control`` module ``name`` is in; '' for control's shared root, None
    outside control."""
    parts = name.split('.')
    if parts[1:2] != ['control']:
        return None
    return parts[2] if len(parts) > 2 and parts[2] in CONTROL_PARTS else ''


def part_violations(sources: dict[str, str] | None = None) -> list[str]:
    """Every import inside ``control`` that breaks :data:`CONTROL_PARTS`, as readable lines
    (lazy imports too; ``sources`` as in :func:`layer_violations`)."""
    sources = sources or {}
    bad = []
    for name, path in MODULES.items():
        part = control_part(name)
        if part is None:
            continue
        allowed = CONTROL_PARTS.get(part, set())
        for mod, _, line in _imports(name, path, False, sources.get(name)):
            target = control_part(mod)
            if target and target != part and target not in allowed:
                bad.append(f'{name}:{line} imports {mod} (control.{target}: '
                           f'control.{part or "root"} may import '
                           f'{", ".join(sorted(allowed)) or "no other part"})')
    return bad


def test_control_parts_hold():
    assert part_violations() == []
    assert {control_part(m) for m in MODULES} >= {'synthesis', 'simulation', 'identification',
                                                   ''}


@pytest.mark.parametrize('module, line, words', [
    ('nonfragile_tracker.control.simulation.tracker', 'from ..synthesis import lmi',
     'imports nonfragile_tracker.control.synthesis.lmi (control.synthesis: '
     'control.simulation may import no other part)'),
    ('nonfragile_tracker.control.simulation.model',
     'def f():\n    from ..synthesis.problem import Problem',
     'imports nonfragile_tracker.control.synthesis.problem'),
    ('nonfragile_tracker.control.simulation.plant', 'from ..identification import monitor',
     'control.simulation may import no other part'),
    ('nonfragile_tracker.control.synthesis.lmi', 'from ..simulation.tracker import Tracker',
     'control.synthesis may import identification'),
    ('nonfragile_tracker.control.identification.monitor', 'from ..synthesis import sdp',
     'control.identification may import simulation'),
    ('nonfragile_tracker.control.validate', 'from .simulation import tracker',
     'control.root may import no other part'),
])
def test_the_part_check_fails_on_a_planted_import(module, line, words):
    source = MODULES[module].read_text() + '\n' + line + '\n'
    bad = part_violations({module: source})
    assert len(bad) == 1 and words in bad[0], bad


def test_every_internal_import_names_an_existing_module():
    """No module imports a path that is no module of today's tree (for example an old flat
    ``control.loop``, now ``control.simulation.tracker`` and ``.plant``)."""
    bad = [(name, mod, line) for name, path in MODULES.items()
           for mod, _, line in _imports(name, path, False)
           if mod not in MODULES and mod.rpartition('.')[0] not in MODULES]
    assert bad == []
    flat = [name for name, path in MODULES.items()
            if control_part(name) and path.name != '__init__.py']
    old = {'nonfragile_tracker.control.' + name.rpartition('.')[2] for name in flat}
    assert not old & set(MODULES)


def test_tests_and_benchmarks_use_the_new_control_paths():
    """test/ and benchmarks/ name ``control``'s modules by their part (but
    :data:`OLD_PATHS_ON_PURPOSE`)."""
    stems = '|'.join(sorted({n.rpartition('.')[2] for n, p in MODULES.items()
                             if control_part(n) and p.name != '__init__.py'}))
    old = re.compile(rf'nonfragile_tracker[./]control(?:[./]| import )({stems})\b')
    root = PKG.parent
    bad = [f'{path.relative_to(root)}:{text[:m.start()].count(chr(10)) + 1}: {m[0]}'
           for folder in ('test', 'benchmarks') for path in sorted((root / folder).rglob('*.py'))
           if path.relative_to(root).as_posix() not in OLD_PATHS_ON_PURPOSE
           for text in [path.read_text()] for m in old.finditer(text)]
    assert bad == []


#: Files that name the old flat paths on purpose: the benchmark that reads identify.py of an
#: old commit (git show of its path then).
OLD_PATHS_ON_PURPOSE = {'benchmarks/sections/identify.py'}


def test_every_module_is_seen():
    assert {'nonfragile_tracker.cli', 'nonfragile_tracker.commands.synthesis',
            'nonfragile_tracker.workflows.runner', 'nonfragile_tracker.errors'} <= set(MODULES)


@pytest.mark.parametrize('name', [m for m in MODULES if not (
    m == 'nonfragile_tracker.cli' or m.startswith('nonfragile_tracker.commands'))])
def test_library_never_imports_the_cli_or_a_command_module(name):
    bad = [(mod, line) for mod, _, line in _imports(name, MODULES[name], False)
           if mod == 'nonfragile_tracker.cli' or mod.startswith('nonfragile_tracker.commands')]
    assert bad == [], f'{name} imports the CLI layer: {bad}'


def test_no_private_name_is_imported_across_modules():
    bad = [(name, mod, what, line) for name, path in MODULES.items()
           for mod, what, line in _imports(name, path, False)
           if what and what.startswith('_') and not what.startswith('__')]
    assert bad == []


def test_no_import_cycle_among_module_level_imports():
    """Module-level imports, those for type checkers included, form no cycle."""
    graph = {name: {mod for mod, _, _ in _imports(name, path, True) if mod in MODULES}
             for name, path in MODULES.items()}
    # a package's __init__ is imported with each of its modules: an edge to it is no cycle
    state: dict[str, int] = {}
    cycles = []

    def visit(node, stack):
        state[node] = 1
        for nxt in graph[node]:
            if nxt == node or node.startswith(nxt + '.'):
                continue
            if state.get(nxt) == 1:
                cycles.append(stack[stack.index(nxt):] + [nxt])
            elif nxt not in state:
                visit(nxt, stack + [nxt])
        state[node] = 2

    for name in graph:
        if name not in state:
            visit(name, [name])
    assert cycles == []


def test_cli_is_argparse_only():
    """cli.py defines the parser and main; at import time it loads only os, sys and errors
    (so Ctrl-C during the heavy imports happens inside main, see test_cli_interrupt), and
    build_parser imports argparse and the command modules."""
    tree = ast.parse(MODULES['nonfragile_tracker.cli'].read_text())
    functions = {n.name for n in tree.body if isinstance(n, ast.FunctionDef)}
    assert functions == {'build_parser', 'main'}
    stdlib = {a.name for n in tree.body if isinstance(n, ast.Import) for a in n.names}
    assert stdlib <= {'os', 'sys'}
    top = {n.module for n in tree.body if isinstance(n, ast.ImportFrom)}
    assert top <= {'__future__', 'typing', 'errors'}, top
    internal = {mod for mod, _, _ in _imports('nonfragile_tracker.cli',
                                               MODULES['nonfragile_tracker.cli'], False)}
    assert internal == {'nonfragile_tracker.errors'}, internal
    build = next(n for n in tree.body if isinstance(n, ast.FunctionDef)
                 and n.name == 'build_parser')
    assert {a.name for n in ast.walk(build) if isinstance(n, ast.Import)
            for a in n.names} <= {'argparse', 'importlib'}


def test_every_command_module_registers():
    import argparse
    import importlib
    names = [m for m in MODULES if m.startswith('nonfragile_tracker.commands.') and any(
        isinstance(n, ast.FunctionDef) and n.name == 'register'
        for n in ast.parse(MODULES[m].read_text()).body)]
    assert len(names) >= 5       # the others are helpers (argparse types)
    from nonfragile_tracker.cli import COMMANDS
    assert {f'nonfragile_tracker.commands.{m}' for m in COMMANDS} == set(names)
    for name in names:
        parser = argparse.ArgumentParser()
        sub = parser.add_subparsers(dest='command')
        importlib.import_module(name).register(sub)
        assert sub.choices, f'{name}.register added no command'
        for choice in sub.choices.values():
            assert choice.get_default('func') is not None or choice._subparsers is not None
