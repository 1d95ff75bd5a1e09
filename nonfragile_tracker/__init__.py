"""Non-fragile LMI trajectory tracking of delayed wheeled mobile robots (ROS 2 Jazzy)."""
