"""Package structure: CLI layering, no import cycles, no private name across modules."""
from __future__ import annotations

import ast
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


def _imports(name: str, path: Path, top_level_only: bool):
    """(imported module, imported names, line) of ``path``, package-internal only."""
    tree = ast.parse(path.read_text())
    package = name if path.name == '__init__.py' else name.rpartition('.')[0]
    nodes = tree.body if top_level_only else list(ast.walk(tree))
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


def test_every_module_is_seen():
    assert {'nonfragile_tracker.cli', 'nonfragile_tracker.commands.synthesis',
            'nonfragile_tracker.runner', 'nonfragile_tracker.errors'} <= set(MODULES)


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
