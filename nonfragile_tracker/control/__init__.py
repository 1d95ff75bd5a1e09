"""The ROS-free control core, in three parts.

:mod:`~nonfragile_tracker.control.synthesis`
    Gains and their certificates (numpy/scipy/cvxpy).
:mod:`~nonfragile_tracker.control.simulation`
    The step functions the nodes run and the in-process loops over them (no cvxpy).
:mod:`~nonfragile_tracker.control.identification`
    Latency and lags from commands and odometry; the runtime certificate monitor.

:mod:`~nonfragile_tracker.control.validate`, the one shape/number validator, is shared by
the three.  Nothing here imports rclpy, rosbags or the package's ROS layers; names are
imported from their modules, the packages hold only their docstrings.

See doc/developing.md, sections "Lint and types" (the parts and their layers) and "Layout".
"""
