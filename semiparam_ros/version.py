"""The package version: checkpoints and ``semiparam_ros.__version__`` read it (setup.py repeats it)."""

__version__ = "0.1.0"
