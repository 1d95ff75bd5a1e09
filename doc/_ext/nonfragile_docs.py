"""Sphinx directives of the package documentation: generated, so they cannot drift.

``node-parameters NODE``
    The parameter table of one node, rendered from the node module's ``PARAMS`` (the
    :class:`nonfragile_tracker.nodes.common.Param` declarations the node declares with
    descriptors): name, type, default, range, read-only, description.
``launch-arguments FILE``
    The arguments a launch file in ``launch/`` declares (``DeclareLaunchArgument``: name,
    default, choices, description), read from its source with ``ast`` (launch itself need
    not be installed).
``cli-help COMMAND [SUBCOMMAND]``
    The ``--help`` text of a command of ``nonfragile_tracker`` (argparse, as the user
    sees it), so the CLI reference lists every option of today's code.
``automodules PACKAGE``
    ``automodule`` for every module of a package, in name order, each under a rubric, so a
    new module appears in the API reference without editing the docs.
``modules PACKAGE``
    A list of a package's modules with their docstrings' first lines (the Layout section of
    doc/developing.md), so a new module needs no entry there.
"""
from __future__ import annotations

import importlib
import importlib.util
import re
import pkgutil
from pathlib import Path
from typing import Any

from docutils import nodes
from docutils.statemachine import StringList
from sphinx.util.docutils import SphinxDirective

#: node name -> module holding its ``PARAMS``
NODE_MODULES = {name: f'nonfragile_tracker.nodes.{name}'
                for name in ('reference', 'plant', 'tracker', 'recorder', 'bringup')}


def _type_name(param: Any) -> str:
    """The ROS parameter type of a declaration, as ``declare`` infers it."""
    from rcl_interfaces.msg import ParameterType
    if param.type is not None:
        names = {v: k for k, v in vars(ParameterType).items()
                 if k.startswith('PARAMETER_') and isinstance(v, int)}
        name = names[param.type].removeprefix('PARAMETER_').lower()
        return name.replace('_array', '[]')
    value = param.default
    if isinstance(value, list):
        inner = type(value[0]) if value else float
        return {float: 'double[]', int: 'integer[]', str: 'string[]'}[inner]
    return {bool: 'bool', int: 'integer', float: 'double', str: 'string'}[type(value)]


def _default(param: Any) -> str:
    value = param.default
    if value is None:
        return '(none: from a file or -p)'
    if isinstance(value, bool):
        return 'true' if value else 'false'     # as in a parameter file
    if isinstance(value, list) and len(value) > 4 and len(set(value)) == 1:
        return f'[{value[0]!r}] x {len(value)}'
    return repr(value) if isinstance(value, str) else str(value).replace("'", '')


def _range(param: Any) -> str:
    if param.low is None and param.high is None:
        return ''
    low = '' if param.low is None else f'{param.low:g}'
    high = '' if param.high is None else f'{param.high:g}'
    return f'[{low}, {high}]'


def declared_parameters(node: str) -> list[Any]:
    """Every parameter ``node`` declares: its module's ``PARAMS`` and then each other
    module-level list named ``*_PARAMS`` (the tracker's ``MONITOR_PARAMS``), in source order."""
    from nonfragile_tracker.nodes.common import Param
    module = importlib.import_module(NODE_MODULES[node])
    names = ['PARAMS'] + [n for n, v in vars(module).items() if n.endswith('_PARAMS')
                          and isinstance(v, list) and v and all(isinstance(p, Param) for p in v)]
    return [p for n in names for p in getattr(module, n)]


def parameter_rows(node: str) -> list[list[str]]:
    """Rows (name, type, default, range, read-only, description) of ``node``'s table."""
    return [[p.name, _type_name(p), _default(p), _range(p), 'yes' if p.read_only else '',
             p.description] for p in declared_parameters(node)]


def _table(header: list[str], rows: list[list[str]], widths: list[int]) -> nodes.table:
    table = nodes.table(classes=['longtable'])
    group = nodes.tgroup(cols=len(header))
    table += group
    for width in widths:
        group += nodes.colspec(colwidth=width)

    def row(cells: list[str], literal_first: bool) -> nodes.row:
        out = nodes.row()
        for i, text in enumerate(cells):
            entry = nodes.entry()
            para = nodes.paragraph()
            para += nodes.literal(text, text) if (literal_first and i == 0) else nodes.Text(text)
            entry += para
            out += entry
        return out

    head = nodes.thead()
    head += row(header, False)
    group += head
    body = nodes.tbody()
    for cells in rows:
        body += row(cells, True)
    group += body
    return table


class NodeParameters(SphinxDirective):
    """``node-parameters NODE``: the node's parameter table from its declarations."""

    required_arguments = 1
    has_content = False

    def run(self) -> list[nodes.Node]:
        node = self.arguments[0]
        if node not in NODE_MODULES:
            raise self.error(f'node-parameters: unknown node {node!r}; '
                             f'one of {sorted(NODE_MODULES)}')
        self.env.note_dependency(importlib.import_module(NODE_MODULES[node]).__file__)
        header = ['parameter', 'type', 'default', 'range', 'read-only', 'description']
        return [_table(header, parameter_rows(node), [14, 8, 10, 8, 6, 54])]


def _launch_value(node: Any) -> str:
    """A launch argument's default as the user sees it (``config`` = the installed config)."""
    import ast
    if isinstance(node, ast.Constant):
        return str(node.value) if node.value != '' else '(empty)'
    if (isinstance(node, ast.Call) and ast.unparse(node.func) == 'os.path.join'
            and len(node.args) == 2 and isinstance(node.args[1], ast.Constant)):
        return f'<share>/{ast.unparse(node.args[0])}/{node.args[1].value}'
    return ast.unparse(node)


def launch_argument_rows(path: Any) -> list[list[str]]:
    """Rows (name, default, choices, description) of each ``DeclareLaunchArgument``."""
    import ast
    rows = []
    for node in ast.walk(ast.parse(path.read_text())):
        if not (isinstance(node, ast.Call)
                and getattr(node.func, 'id', None) == 'DeclareLaunchArgument'):
            continue
        keywords = {k.arg: k.value for k in node.keywords}
        choices = keywords.get('choices')
        rows.append([
            node.args[0].value,
            _launch_value(keywords['default_value']) if 'default_value' in keywords else '',
            ', '.join(ast.literal_eval(choices)) if choices is not None else '',
            ast.literal_eval(keywords['description']) if 'description' in keywords else ''])
    return rows


class LaunchArguments(SphinxDirective):
    """``launch-arguments FILE``: the launch file's declared arguments as a table."""

    required_arguments = 1

    def run(self) -> list[nodes.Node]:
        from pathlib import Path
        path = Path(self.env.srcdir).parent / 'launch' / self.arguments[0]
        if not path.is_file():
            raise self.error(f'launch-arguments: no launch file {path}')
        self.env.note_dependency(str(path))
        header = ['argument', 'default', 'choices', 'description']
        return [_table(header, launch_argument_rows(path), [18, 30, 14, 38])]


def command_parsers() -> dict[str, Any]:
    """Command name (``'bag report'`` for nested ones) -> its argparse parser."""
    import argparse

    from nonfragile_tracker.cli import build_parser

    def walk(parser: argparse.ArgumentParser, prefix: str) -> dict[str, Any]:
        out = {}
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for name, sub in action.choices.items():
                    full = f'{prefix} {name}'.strip()
                    out[full] = sub
                    out.update(walk(sub, full))
        return out

    return walk(build_parser(), '')


class CliHelp(SphinxDirective):
    """``launch-arguments FILE``
    The arguments a launch file in ``launch/`` declares (``DeclareLaunchArgument``: name,
    default, choices, description), read from its source with ``ast`` (launch itself need
    not be installed).
``cli-help COMMAND [SUBCOMMAND]``: the command's ``--help`` as a literal block."""

    required_arguments = 1
    optional_arguments = 1

    def run(self) -> list[nodes.Node]:
        import os
        name = ' '.join(self.arguments)
        parsers = command_parsers()
        if name not in parsers:
            raise self.error(f'cli-help: no command {name!r}; commands: {sorted(parsers)}')
        old = os.environ.get('COLUMNS')
        os.environ['COLUMNS'] = '92'  # argparse wraps to the terminal width: fix it
        try:
            text = parsers[name].format_help()
        finally:
            if old is None:
                os.environ.pop('COLUMNS', None)
            else:
                os.environ['COLUMNS'] = old
        text = text.replace('usage: python -m nonfragile_tracker.cli', 'usage: nonfragile_tracker')
        block = nodes.literal_block(text, text, language='text')
        return [block]


class AutoModules(SphinxDirective):
    """``launch-arguments FILE``
    The arguments a launch file in ``launch/`` declares (``DeclareLaunchArgument``: name,
    default, choices, description), read from its source with ``ast`` (launch itself need
    not be installed).
``cli-help COMMAND [SUBCOMMAND]``
    The ``--help`` text of a command of ``nonfragile_tracker`` (argparse, as the user
    sees it), so the CLI reference lists every option of today's code.
``automodules PACKAGE``: ``automodule`` for each module of the package (its subpackages
    have pages of their own, so a new module or folder needs no entry here)."""

    required_arguments = 1

    def run(self) -> list[nodes.Node]:
        package = importlib.import_module(self.arguments[0])
        names = sorted(m.name for m in pkgutil.iter_modules(package.__path__) if not m.ispkg)
        lines = StringList()
        source = self.get_source_info()[0]
        for name in names:
            full = f'{package.__name__}.{name}'
            for text in (f'.. rubric:: ``{full}``', '', f'.. automodule:: {full}', ''):
                lines.append(text, source)
        container = nodes.container()
        self.state.nested_parse(lines, self.content_offset, container)
        return container.children


class ModuleList(SphinxDirective):
    """``modules PACKAGE``: a bullet list of the package's modules, each with the first line
    of its docstring (read with ``ast``, nothing imported), so the Layout section of
    doc/developing.md is derived from the modules and a new one needs no entry there."""

    required_arguments = 1

    def run(self) -> list[nodes.Node]:
        import ast
        spec = importlib.util.find_spec(self.arguments[0])
        if spec is None or not spec.submodule_search_locations:
            raise self.error(f'modules: {self.arguments[0]!r} is not a package')
        folder = Path(next(iter(spec.submodule_search_locations)))
        lines = StringList()
        source = self.get_source_info()[0]
        for path in sorted(folder.glob('*.py')):
            if path.stem == '__init__':
                continue
            doc = ast.get_docstring(ast.parse(path.read_text())) or ''
            summary = doc.strip().splitlines()[0] if doc.strip() else ''
            # roles as plain literals: the list is parsed as the page's markup (MyST or rST)
            summary = re.sub(r':[\w:]+:`~?([^`<]+?)(?: <[^>]+>)?`', r'``\1``', summary)
            lines.append(f'- ``{path.stem}``: {summary}', source)
        container = nodes.container()
        self.state.nested_parse(lines, self.content_offset, container)
        return container.children


_CITATION_USE = re.compile(r'\[(\d+)\]_')
_CITATION_DEF = re.compile(r'^(\s*)\.\. \[(\d+)\]', re.MULTILINE)


def unique_citations(app: Any, what: str, name: str, obj: Any, options: Any,
                     lines: list[str]) -> None:
    """Give a docstring's numbered citations (``[1]_``, ``.. [1]``) labels of its own.

    Several functions of one module cite their sources as ``[1]``; on one page docutils
    would see duplicate targets.  numpydoc renames them the same way.
    """
    tag = re.sub(r'\W', '-', name.rsplit('.', 1)[-1]).strip('-') or 'ref'
    for i, line in enumerate(lines):
        line = _CITATION_USE.sub(lambda m: f'[{tag}-{m.group(1)}]_', line)
        lines[i] = _CITATION_DEF.sub(lambda m: f'{m.group(1)}.. [{tag}-{m.group(2)}]', line)


def setup(app: Any) -> dict[str, Any]:
    """Register the directives and the docstring hook."""
    app.connect('autodoc-process-docstring', unique_citations)
    app.add_directive('node-parameters', NodeParameters)
    app.add_directive('automodules', AutoModules)
    app.add_directive('modules', ModuleList)
    app.add_directive('cli-help', CliHelp)
    app.add_directive('launch-arguments', LaunchArguments)
    return {'version': '1', 'parallel_read_safe': True, 'parallel_write_safe': True}
