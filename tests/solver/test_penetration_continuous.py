"""The penetration constraint holds on the continuous path (solver.constraints.penetration): its value is
the deepest point of each Hermite curve between two quadrature points, checked against the curve sampled
a hundred thousand times (an independent brute force), against hand-built curves whose deepest point is
known in closed form (a parabola over a plane, a straight line through a box's edge), and its gradient in a box
against central differences."""
import numpy as np
import pytest

from solver.constraints.penetration import _curve, _power, box_minimum, plane_minimum
from solver.surfaces import StaticSurfaces

FLOOR = StaticSurfaces(np.zeros((1, 3)), np.array([[0.0, 0.0, 1.0]]), np.zeros((0, 3)), np.zeros((0, 3, 3)),
                       np.zeros((0, 3)), ("floor",))
# a step 0.2 m high: x in [0, 1], y in [-0.5, 0.5], z in [0, 0.2]
STEP = StaticSurfaces(np.zeros((0, 3)), np.zeros((0, 3)), np.array([[0.5, 0.0, 0.1]]), np.eye(3)[None],
                      np.array([[0.5, 0.5, 0.1]]), ("step",))


def _hermite_coefficients(p0, v0, p1, v1, h):
    """(4, 1, 3) the coefficients p0, h v0, p1, h v1 of one curve."""
    return np.array([p0, h * np.asarray(v0), p1, h * np.asarray(v1)], float)[:, None, :]


def _box(surfaces, b=0):
    """(center, rot, half) of box b."""
    return surfaces.box_center[b], surfaces.box_rot[b], surfaces.box_half[b]


def _random_curves(rng, n=200):
    """(4, n, 3) Hermite curves over 5 ms at up to ~10 m/s around the step."""
    p0 = rng.uniform([-0.1, -0.6, -0.05], [1.1, 0.6, 0.3], size=(n, 3))
    p1 = p0 + rng.normal(scale=0.02, size=(n, 3))
    v0, v1 = rng.normal(scale=3.0, size=(n, 3)), rng.normal(scale=3.0, size=(n, 3))
    h = 0.005
    return np.stack([p0, h * v0, p1, h * v1])


def _brute_minimum(C, distance, n=100_001):
    """(q,) the least distance over n evenly spaced points of each curve."""
    best = np.full(C.shape[1], np.inf)
    for u in np.array_split(np.linspace(0.0, 1.0, n), 50):
        points = _curve(_power(C)[:, None], np.broadcast_to(u[:, None], (len(u), C.shape[1])))  # (len(u), q, 3)
        best = np.minimum(best, distance(points)[0].min(axis=0))
    return best


def test_a_parabola_dipping_into_the_floor_has_its_vertex_as_deepest_point():
    # a site falling into the floor and rising again: z = a (u - 0.3)^2 - 1 mm on the interval
    h = 0.005
    a = 0.004
    z = lambda u: a * (u - 0.3) ** 2 - 0.001  # noqa: E731
    dz = lambda u: 2 * a * (u - 0.3) / h  # noqa: E731 (per second)
    C = _hermite_coefficients([0, 0, z(0)], [0, 0, dz(0)], [0, 0, z(1)], [0, 0, dz(1)], h)
    u, d = plane_minimum(C, FLOOR.plane_point[0], FLOOR.plane_normal[0])
    assert u[0] == pytest.approx(0.3, abs=1e-12)
    assert d[0] == pytest.approx(-0.001, abs=1e-15)


@pytest.mark.parametrize("seed", range(4))
def test_plane_minimum_matches_a_brute_force_search(seed):
    rng = np.random.default_rng(seed)
    C = rng.normal(scale=0.01, size=(4, 50, 3))
    normal = rng.normal(size=3)
    normal /= np.linalg.norm(normal)
    point = rng.normal(scale=0.01, size=3)
    _, d = plane_minimum(C, point, normal)
    brute = _brute_minimum(C, lambda x: ((x - point) @ normal, None))
    np.testing.assert_allclose(d, brute, atol=1e-9)  # the brute force's own grid error is ~1e-10 m here


def test_a_heel_clipping_a_step_edge_is_caught_between_samples():
    # a heel 2 cm short of the step's far edge (x = 1) and level with its top (z = 0.2) moves 30 mm along x
    # and 12 mm down over one interval, and leaves through the side: inside, its distance is the larger of
    # (x - 1) and (z - 0.2), -0.02 + 0.03 u and -0.012 u, equal at u = 0.02 / 0.042, where the deepest
    # point is 0.24 / 42 m (5.71 mm); the nine samples of the interval see 5 mm of it
    h = 0.005
    v = np.array([0.03, 0.0, -0.012]) / h
    C = _hermite_coefficients([0.98, 0, 0.2], v, [1.01, 0, 0.188], v, h)
    u, d, g = box_minimum(C, *_box(STEP))
    assert u[0] == pytest.approx(0.02 / 0.042, abs=1e-12)
    assert d[0] == pytest.approx(-0.24 / 42, abs=1e-15)
    # the gradient at the kink combines the side's normal (x) and the top's (z) so that its slope along the
    # curve is zero: mu x + (1 - mu) z with 0.03 mu - 0.012 (1 - mu) = 0
    mu = 0.012 / 0.042
    np.testing.assert_allclose(g[0], [mu, 0.0, 1 - mu], atol=1e-12)


@pytest.mark.parametrize("seed", range(4))
def test_box_minimum_matches_a_brute_force_search(seed):
    # against the box's exact signed distance: equal inside the box, where the constraint can be active; outside
    # (at an edge or corner) the faces' largest distance is below the Euclidean one but still positive, so that the
    # constraint -min d <= tol holds on the same curves
    rng = np.random.default_rng(seed)
    C = _random_curves(rng)
    _, d, _ = box_minimum(C, *_box(STEP))
    brute = _brute_minimum(C, lambda x: STEP.box_distance(x, 0), n=20_001)
    inside = brute < 0
    assert inside.sum() > 20
    # the deepest point inside, to the brute force's resolution (a 10 m/s site moves 2.5 um a sample)
    np.testing.assert_allclose(d[inside], brute[inside], atol=3e-6)
    assert (d <= brute + 1e-12).all()  # never shallower than the curve's own samples
    assert (d[brute > 3e-6] > 0).all()  # out of the box where the curve is


@pytest.mark.parametrize("seed", range(3))
def test_box_minimum_is_the_least_of_the_faces_largest_distance_on_a_turned_box(seed):
    # a box turned 0.3 rad about z and tilted 0.1 rad about x: the value is the least over the curve of the largest
    # face distance, to the brute force's resolution, and never above it
    c, s, ct, st = np.cos(0.3), np.sin(0.3), np.cos(0.1), np.sin(0.1)
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ np.array([[1.0, 0.0, 0.0], [0.0, ct, -st], [0.0, st, ct]])
    center, half = np.array([0.5, 0.0, 0.1]), np.array([0.5, 0.5, 0.1])

    def faces(x):
        local = (x - center) @ rot
        return (abs(local) - half).max(axis=-1), None

    C = _random_curves(np.random.default_rng(100 + seed), 300)
    u, d, _ = box_minimum(C, center, rot, half)
    brute = _brute_minimum(C, faces, n=100_001)
    np.testing.assert_allclose(d, brute, atol=6e-7)  # 1e-5 of u at up to 0.06 m per unit u
    assert (d <= brute + 1e-12).all()
    np.testing.assert_allclose(faces(_curve(_power(C), u))[0], d, atol=1e-15)  # the value is the curve's at u


def test_box_gradient_matches_central_differences():
    # d's gradient in the curve's coefficients: grad d at the deepest point times the Hermite weights there
    # (envelope and Danskin theorems, module docstring), away from ties between candidates
    C = _random_curves(np.random.default_rng(7), 60)
    u, d, g = box_minimum(C, *_box(STEP))
    H = np.stack([2 * u**3 - 3 * u**2 + 1, u**3 - 2 * u**2 + u, -2 * u**3 + 3 * u**2, u**3 - u**2])
    eps, checked = 1e-7, 0
    for j in np.flatnonzero(d < -1e-3):
        for a, c in ((0, 2), (2, 0), (3, 1)):
            Cp, Cm = C.copy(), C.copy()
            Cp[a, j, c] += eps
            Cm[a, j, c] -= eps
            fd = (box_minimum(Cp[:, j:j + 1], *_box(STEP))[1] - box_minimum(Cm[:, j:j + 1], *_box(STEP))[1])[0] / (2 * eps)
            assert fd == pytest.approx(H[a, j] * g[j, c], abs=1e-6)
            checked += 1
    assert checked >= 30
