"""Shared fixtures: a small inline figure (free root, ball joints, four contact sites) and a scene."""
import os

from runner.environment import apply_defaults

apply_defaults()  # before mujoco and numpy are imported

import mujoco  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from hypothesis import settings  # noqa: E402

# CI (CI=true) replays the same examples every run, so a submission is judged on its code, not on the
# examples a random seed happened to draw; locally hypothesis keeps exploring and remembers failures.
settings.register_profile("ci", derandomize=True, database=None)
if os.environ.get("CI"):
    settings.load_profile("ci")

TOY_SCENE = """
<mujoco>
  <custom>
    <text name="figure:foot:left" data="l_heel l_toe"/>
    <text name="figure:foot:right" data="r_heel r_toe"/>
    <numeric name="figure:flexion:l_knee" data="0 1 0"/>
    <numeric name="figure:flexion:r_knee" data="0 1 0"/>
  </custom>
  <worldbody>
    <geom name="floor" type="plane" size="5 5 .1"/>
    <geom name="step" type="box" pos="1.5 0 .1" size=".4 1 .1"/>
    <body name="pelvis" pos="0 0 1">
      <freejoint name="root"/>
      <geom type="box" size=".1 .15 .1" mass="10"/>
      <body name="l_thigh" pos="0 .1 -.1">
        <joint name="l_hip" type="ball"/>
        <geom type="capsule" fromto="0 0 0 0 0 -.4" size=".05"/>
        <body name="l_shin" pos="0 0 -.4">
          <joint name="l_knee" type="ball"/>
          <geom type="capsule" fromto="0 0 0 0 0 -.4" size=".04"/>
          <site name="l_heel" pos="-.05 0 -.45"/>
          <site name="l_toe" pos=".15 0 -.45"/>
        </body>
      </body>
      <body name="r_thigh" pos="0 -.1 -.1">
        <joint name="r_hip" type="ball"/>
        <geom type="capsule" fromto="0 0 0 0 0 -.4" size=".05"/>
        <body name="r_shin" pos="0 0 -.4">
          <joint name="r_knee" type="ball"/>
          <geom type="capsule" fromto="0 0 0 0 0 -.4" size=".04"/>
          <site name="r_heel" pos="-.05 0 -.45"/>
          <site name="r_toe" pos=".15 0 -.45"/>
        </body>
      </body>
    </body>
  </worldbody>
</mujoco>
"""


@pytest.fixture(scope="session")
def toy_model():
    return mujoco.MjModel.from_xml_string(TOY_SCENE)


def shipped_standing():
    """The shipped run_and_step figure standing in its first keyframe's pose: (model, keyframes, keyframe-file
    info, StateLayout, q (nq,)) with every quaternion of q made unit (the file's 6 digits leave norms 1e-6 off)."""
    import solver
    from solver.layout import StateLayout

    model = solver.load_model(solver.shipped("run_and_step.xml"))
    keyframes, info = solver.read_keyframes(solver.shipped("run_and_step.keyframes.json"), model)
    layout = StateLayout.from_model(model)
    q = keyframes.values[0].copy()
    for slot in layout.quat_slots:
        q[slot] /= np.linalg.norm(q[slot])
    return model, keyframes, info, layout, q


def random_qpos(rng, layout, n, spread=0.6, scale=(0.8, 1.3)):
    """(n, nq) random qpos with non-unit quaternions of moderate rotation, root near (0, 0, 1)."""
    Y = np.zeros((n, layout.nq))
    Y[:, :3] = [0, 0, 1] + rng.normal(scale=0.1, size=(n, 3))
    for slot in layout.quat_slots:
        q = np.concatenate([np.ones((n, 1)), rng.normal(scale=spread, size=(n, 3))], axis=1)
        q /= np.linalg.norm(q, axis=1, keepdims=True)
        Y[:, slot] = q * rng.uniform(*scale, size=(n, 1))
    return Y


def fd_gradient(fun, X, h=1e-6):
    """Central finite-difference gradient of a scalar fun at X (any shape)."""
    G = np.zeros_like(X)
    it = np.nditer(X, flags=["multi_index"])
    for _ in it:
        i = it.multi_index
        Xp, Xm = X.copy(), X.copy()
        Xp[i] += h
        Xm[i] -= h
        G[i] = (fun(Xp) - fun(Xm)) / (2 * h)
    return G


def pytest_collection_modifyitems(config, items):
    """Everything under tests/e2e/ (whole command runs through the CLI) is `slow`; other slow tests
    carry @pytest.mark.slow themselves. `pytest -m "not slow"` is the fast part."""
    from pathlib import Path  # here, not at the top: the top of this file belongs to the environment setup

    e2e = Path(__file__).resolve().parent / "e2e"
    for item in items:
        if e2e in Path(str(item.path)).resolve().parents:
            item.add_marker(pytest.mark.slow)


def in_ci() -> bool:
    """True when the CI variable is set to anything but "", "0", "false" or "no" (.ci/run sets CI=true)."""
    return os.environ.get("CI", "").strip().lower() not in ("", "0", "false", "no")


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    """In CI a skipped test marked `client` (it runs a real client program: Chromium, the Khronos glTF
    validator, Blender's bpy) is a failure: CI installs the clients, so a skip there means a test that
    did not run. Locally these tests skip, naming what to install (README "Full test suite")."""
    outcome = yield
    report = outcome.get_result()
    if not item.get_closest_marker("client"):
        return
    if report.skipped and not hasattr(report, "wasxfail") and in_ci():
        reason = report.longrepr[2] if isinstance(report.longrepr, tuple) else str(report.longrepr)
        report.outcome = "failed"
        report.longrepr = f"a real-client test skipped in CI (CI={os.environ['CI']}): {reason}"
    seen = _CLIENT_TESTS.setdefault(item.nodeid, ["passed", 0.0])
    seen[1] += report.duration
    if report.outcome != "passed":
        seen[0] = report.outcome


_CLIENT_TESTS: dict = {}  # node id -> [outcome, seconds over setup, call and teardown]


def pytest_terminal_summary(terminalreporter):
    """One line per `client` test that ran: its outcome and time, so a log shows the clients were used."""
    if _CLIENT_TESTS:
        terminalreporter.section("real-client tests (Chromium, glTF validator, Blender)")
        for nodeid, (outcome, seconds) in _CLIENT_TESTS.items():
            terminalreporter.write_line(f"{outcome:8} {seconds:6.1f} s  {nodeid}")
