"""dynsplines runner: command line, rendering, import and export around the `solver` package."""
from runner.environment import apply_defaults

apply_defaults()  # before anything below imports mujoco or numpy
