"""Types, strict part: every module of the package (test_docstrings.CHECKED holds them all,
and every package ``__init__``) is type-checked with every per-module flag of mypy's
--strict (setup.cfg ``[mypy-...]`` sections; test_types.py runs mypy itself)."""
from __future__ import annotations

import configparser
import fnmatch

from conftest import ROOT
from test_docstrings import CHECKED

#: The per-module flags of ``mypy --strict`` the checked modules are held to.
STRICT = ('disallow_untyped_defs', 'disallow_incomplete_defs', 'disallow_any_generics',
          'disallow_untyped_calls', 'disallow_untyped_decorators', 'disallow_subclassing_any',
          'no_implicit_reexport', 'strict_equality', 'extra_checks', 'warn_return_any')


def strict_flags(cfg: configparser.ConfigParser, module: str) -> set[str]:
    """The STRICT flags set to True for ``module`` by the ``[mypy-PATTERN,...]`` sections."""
    on: set[str] = set()
    for name in cfg.sections():
        if not name.startswith('mypy-'):
            continue
        patterns = [p.strip() for p in name[len('mypy-'):].split(',')]
        if any(fnmatch.fnmatchcase(module, p) for p in patterns):
            on |= {f for f in STRICT if cfg[name].getboolean(f, fallback=False)}
    return on


def _config() -> configparser.ConfigParser:
    cfg = configparser.ConfigParser()
    cfg.read(ROOT / 'setup.cfg')
    return cfg


def test_every_module_is_typed_strictly():
    cfg = _config()
    packages = ['.'.join(p.relative_to(ROOT).parent.parts)
                for p in (ROOT / 'nonfragile_tracker').rglob('__init__.py')]
    modules = [*CHECKED, *packages]
    lacking = {m: sorted(set(STRICT) - strict_flags(cfg, m)) for m in modules}
    assert not {m: f for m, f in lacking.items() if f}, lacking
    files = [f.strip() for f in cfg['mypy']['files'].split(',') if f.strip()]
    assert files == ['nonfragile_tracker']                # the whole package, every module
    assert cfg['mypy'].getboolean('warn_redundant_casts')


def test_flag_lookup_reads_patterns():
    cfg = configparser.ConfigParser()
    cfg.read_string('[mypy]\n[mypy-a.b,a.c.*]\ndisallow_untyped_defs = True\n'
                    'strict_equality = False\n')
    assert strict_flags(cfg, 'a.b') == {'disallow_untyped_defs'}
    assert strict_flags(cfg, 'a.c.d') == {'disallow_untyped_defs'}
    assert strict_flags(cfg, 'a.d') == set()
