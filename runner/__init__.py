"""dynsplines runner: command line, rendering, import and export around the `solver` package."""
import solver  # noqa: F401  (sets the headless MuJoCo GL backend before mujoco is imported)
