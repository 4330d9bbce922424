"""Process defaults for the command line (a leaf: imports only `os`).

`apply_defaults()` must run before anything imports mujoco or numpy: `runner/__init__.py` calls it
first, and so does `tests/conftest.py`.
"""
from __future__ import annotations

import os

BLAS_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def apply_defaults(environ=None) -> None:
    """Set the GL backend and the BLAS thread count, unless the user already chose them.

    MuJoCo picks its OpenGL backend when it is first imported. With no display (servers, CI) the only
    backend that works is EGL (Mesa's software renderer here), so `MUJOCO_GL=egl` when neither DISPLAY
    nor WAYLAND_DISPLAY is set. A user's own MUJOCO_GL always wins.

    The matrices here are small (hundreds of quadrature points x tens of frames): multithreaded BLAS only
    adds contention, and on a loaded 2-core machine a 0.05 ms product was seen taking 25 ms. One thread
    (OPENBLAS/OMP/MKL_NUM_THREADS=1) unless the user says otherwise; it takes effect only when this runs
    before numpy is imported.

    Args:
        environ: the mapping to change [os.environ].
    """
    env = os.environ if environ is None else environ
    if not env.get("DISPLAY") and not env.get("WAYLAND_DISPLAY"):
        env.setdefault("MUJOCO_GL", "egl")
    for var in BLAS_THREAD_VARIABLES:
        env.setdefault(var, "1")
