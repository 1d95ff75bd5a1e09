"""The CLI's sub-commands, one module per area; each exposes ``register(subparsers)``.

A command function takes the parsed ``args`` and returns an exit code; it calls
library functions (``control``, ``runner``, ``reproduce``, ``golden``, ``bag``) and
only formats their results.  Library modules never import this package.

See doc/cli.md and doc/developing.md, section "Layout"
(``nonfragile_tracker/commands/``).
"""
