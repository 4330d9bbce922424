"""The per-point Jacobian of the inverse dynamics (`solver.id_jacobian`): the analytic engine's reverse
passes against MuJoCo's `mjd_inverseFD` and against central differences of tau along the path, and one
shared tau Jacobian for the torque, root and friction-cone residuals."""
import numpy as np

from solver.id_jacobian import analytic_tau_jacobian, mujoco_tau_jacobian, tau_jacobian
from solver.inverse_dynamics import InverseDynamics
from solver.layout import CONTACT_SITES, StateLayout
from solver.path_context import PathContext
from solver.terms.dynamics import JointTorque, RootResidual, make_engine

from conftest import random_qpos

N = 6


def _path(model, seed=5, height=0.95):
    """(t, Y, Y', Y'') at N points: random poses (non-unit quaternions), velocities and accelerations,
    the feet near the floor."""
    layout = StateLayout.from_model(model)
    rng = np.random.default_rng(seed)
    Y = random_qpos(rng, layout, N, spread=0.3)
    Y[:, 2] = height + 0.02 * rng.normal(size=N)
    return np.linspace(0.0, 1.0, N), Y, rng.normal(size=Y.shape), rng.normal(size=Y.shape)


def test_analytic_tau_jacobian_matches_mjd_inverse_fd(toy_model):
    """The reverse passes of the vectorized engine chained to (Y, Y', Y'') equal MuJoCo's finite-difference
    derivatives (`mjd_inverseFD`, forward differences with step 1e-6: to 1e-5 of the largest entry)
    chained the same way, for every tau row."""
    t, Y, Y1, Y2 = _path(toy_model)
    engine = InverseDynamics(toy_model)
    ctx = PathContext(t, Y, Y1, Y2)
    tmap = JointTorque(toy_model, engine=engine).tmap
    mo, res = ctx.forward(engine, tmap)
    rows = np.arange(res.tau.shape[1])
    an = analytic_tau_jacobian(engine, res, mo, rows)
    fd = mujoco_tau_jacobian(toy_model, res, mo, rows)
    assert np.abs(an).max() > 1.0, "the Jacobian is tiny: the comparison checks nothing"
    np.testing.assert_allclose(an, fd, atol=1e-5 * np.abs(an).max())


def test_tau_jacobian_matches_central_differences_along_the_path(toy_model):
    """d tau / d(Y, Y', Y'') applied to a random direction D equals the central difference of tau along
    D (step 1e-6, through a fresh PathContext: the spline's qpos -> MuJoCo's qvel, qacc -> tau), to 1e-6
    relative."""
    t, Y, Y1, Y2 = _path(toy_model, seed=8)
    engine = make_engine(toy_model)
    tmap = JointTorque(toy_model, engine=engine).tmap
    ctx = PathContext(t, Y, Y1, Y2)
    tj = tau_jacobian(ctx, engine, tmap)
    nv = ctx.forward(engine, tmap)[1].tau.shape[1]
    J = tj.rows(np.arange(nv))  # (3, n, nv, nq)
    rng = np.random.default_rng(2)
    D = [rng.normal(size=Y.shape) for _ in range(3)]
    h = 1e-6

    def tau(eps):
        moved = [a + eps * d for a, d in zip((Y, Y1, Y2), D)]
        engine._cache = None
        return PathContext(t, *moved).forward(engine, tmap)[1].tau

    fd = (tau(h) - tau(-h)) / (2 * h)
    an = sum(np.einsum("nrq,nq->nr", J[k], D[k]) for k in range(3))
    np.testing.assert_allclose(an, fd, rtol=1e-6, atol=1e-6 * np.abs(fd).max())


def test_the_dynamics_terms_share_one_tau_jacobian(toy_model, monkeypatch):
    """Torque and root residuals on one context cost nv reverse passes in all (the tau rows are
    computed once and shared), not nv + 6; and their blocks are the Jacobian their own
    vector-Jacobian products give (`pull`), row by row."""
    engine = make_engine(toy_model, CONTACT_SITES)
    terms = [JointTorque(toy_model, engine=engine), RootResidual(toy_model, engine=engine)]
    t, Y, Y1, Y2 = _path(toy_model, seed=11, height=0.93)
    ctx = PathContext(t, Y, Y1, Y2)
    calls = []
    vjp = engine.vjp
    monkeypatch.setattr(engine, "vjp", lambda *a, **k: calls.append(1) or vjp(*a, **k))
    residuals = [term.residual(ctx) for term in terms]
    nv = ctx.forward(engine, terms[0].tmap)[1].tau.shape[1]
    assert len(calls) == nv
    for term, res in zip(terms, residuals):
        assert np.any(res.r), f"{term.name} is zero on the test path: the check checks nothing"
        n, m = res.r.shape
        for c in range(m):
            g = np.zeros((n, m))
            g[:, c] = 1.0
            pulled = res.pull(g)
            for J, p in zip(res.blocks, pulled):
                want = np.zeros(J[:, c].shape) if p is None else p
                np.testing.assert_allclose(J[:, c], want, rtol=1e-10, atol=1e-10 * (1.0 + np.abs(want).max()))


def test_an_engine_without_a_vectorized_reverse_pass_keeps_the_products(toy_model):
    """With MuJoCo's engine the terms give vector-Jacobian products only (no tau Jacobian)."""
    engine = make_engine(toy_model, backend="mujoco")
    term = JointTorque(toy_model, engine=engine)
    t, Y, Y1, Y2 = _path(toy_model)
    ctx = PathContext(t, Y, Y1, Y2)
    assert tau_jacobian(ctx, engine, term.tmap) is None
    res = term.residual(ctx)
    assert res.blocks is None and res.pull is not None


def test_rows_are_kept_in_the_order_asked(toy_model):
    """Rows asked for again come from the context's one `TauJacobian`, in the order asked."""
    engine = make_engine(toy_model)
    tmap = JointTorque(toy_model, engine=engine).tmap
    t, Y, Y1, Y2 = _path(toy_model, seed=1)
    ctx = PathContext(t, Y, Y1, Y2)
    tj = tau_jacobian(ctx, engine, tmap)
    assert tau_jacobian(ctx, engine, tmap) is tj
    a = tj.rows([7, 3])
    b = tj.rows([3])
    np.testing.assert_array_equal(a[:, :, 1], b[:, :, 0])
