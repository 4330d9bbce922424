"""dynsplines solver: dynamic splines with constraints (Ramamoorthi, Ball & Barr).

The algorithm only: the C2 natural cubic spline through keyframes and variable frames, the objective
terms with their gradients, the nlopt driver and Euler-Lagrange subdivision. No rendering, no CLI.
"""
import os as _os

# MuJoCo picks its OpenGL backend when it is first imported. With no display (servers, CI) the only
# backend that works is EGL (Mesa's software renderer here), so choose it before anything imports
# mujoco. A user's own MUJOCO_GL always wins.
if not _os.environ.get("DISPLAY") and not _os.environ.get("WAYLAND_DISPLAY"):
    _os.environ.setdefault("MUJOCO_GL", "egl")

# The matrices here are small (hundreds of quadrature points x tens of frames): multithreaded BLAS only
# adds contention, and on a loaded 2-core machine a 0.05 ms product was seen taking 25 ms. One thread
# unless the user says otherwise (takes effect when solver is imported before numpy, as the CLI does).
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    _os.environ.setdefault(_var, "1")

from solver.errors import DynsplinesError, InputError  # noqa: E402
from solver.keyframes import Keyframes  # noqa: E402

__all__ = ["DynsplinesError", "InputError", "Keyframes"]
