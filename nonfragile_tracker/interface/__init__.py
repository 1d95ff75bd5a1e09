"""Between the ROS-free core and ROS: names, messages, files and input rules (no rclpy).

:mod:`.topics` (every topic and frame name), :mod:`.msgconv` (messages <-> arrays),
:mod:`.tracker_inputs` (the tracker node's input rules, also run by the replay),
:mod:`.robot` (the robot file), :mod:`.scenario` (the shipped scenario files as objects)
and :mod:`.resources` (where ``config/`` is).  They import the core and the foundation
only, and neither rclpy nor a bag library.

See doc/developing.md, section "Layout".
"""
