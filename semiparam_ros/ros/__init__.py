"""semiparam_ros."""
