"""Non-fragile LMI trajectory tracking of delayed wheeled mobile robots (ROS 2 Jazzy).

See doc/index.md (what the package is for) and doc/developing.md, section "Layout".
"""
