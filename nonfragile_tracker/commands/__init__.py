"""CLI sub-commands by area: each module exposes ``register(subparsers) -> None``.

Layering: :mod:`nonfragile_tracker.cli` (argparse only) -> these modules (parse
arguments, call the library, print, return an exit code) -> the library.  Library
code never imports this package.
"""
