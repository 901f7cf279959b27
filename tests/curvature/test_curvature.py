import numpy as np
import pytest
from numpy.testing import assert_allclose

from volseg import mesh, tessellation
from volseg.analytic import FUNCTIONS
from volseg.curvature import REGISTRY, bending_angles, cotangent_weights, vertex_curvature

ALL = list(REGISTRY)
ORIENTED = [name for name, op in REGISTRY.items() if op.oriented]


def plane_triangulation(n=6):
    """A Kuhn-triangulated 2-D grid on [0, 1]^2 as a graph in R^3 (upward)."""
    s = tessellation.kuhn_simplices((n, n))
    g = np.stack(np.meshgrid(*[np.linspace(0, 1, n)] * 2, indexing="ij"), -1).reshape(-1, 2)
    return g, s


@pytest.mark.parametrize("operator", ALL)
def test_flat_graph_is_zero_n3(operator):
    v, s = tessellation.kuhn_cube_mesh(6, lambda x, y, z: 0.3 * x - 1.7 * y + 0.2 * z + 5)
    h = vertex_curvature(v, s, operator)
    interior = ~mesh.boundary_vertices(s)
    assert interior.sum() == 4**3
    assert_allclose(h[interior], 0, atol=1e-12)
    assert np.isnan(h[~interior]).all()


@pytest.mark.parametrize("operator", ALL)
def test_flat_graph_is_zero_n2(operator):
    g, s = plane_triangulation()
    v = np.c_[g, 0.4 * g[:, 0] - 0.9 * g[:, 1] + 1]
    h = vertex_curvature(v, s, operator)
    interior = ~mesh.boundary_vertices(s)
    assert_allclose(h[interior], 0, atol=1e-12)


def test_polygon_matches_classical_n1_formulas():
    n_sides, r = 48, 2.5
    v, s = tessellation.polygon(n_sides, r)
    half = np.pi / n_sides
    assert_allclose(vertex_curvature(v, s, "unweighted"), 2 * half, rtol=1e-12)
    # psi / |p| with |p| the edge length 2 r sin(pi/N).
    assert_allclose(vertex_curvature(v, s, "weighted"), half / (r * np.sin(half)), rtol=1e-12)
    assert_allclose(vertex_curvature(v, s, "laplace_beltrami"), 1 / r, rtol=1e-12)
    with pytest.raises(ValueError, match="defined for n = 2 and n = 3"):
        vertex_curvature(v, s, "intrinsic")


@pytest.mark.parametrize("dim", [1, 2, 3])
def test_cylinder_weighted_is_one_over_n_r(dim):
    # The derivation's own case: psi = 2 pi / N at every face along the circle, so
    # H = 1/(n r) times the polygon's factor (pi/N) / sin(pi/N), exactly.
    n_around, r = 40, 1.5
    if dim == 1:
        v, s = tessellation.polygon(n_around, r)
    else:
        v, s = tessellation.cylinder(dim, r, n_around=n_around, n_along=7)
    h = vertex_curvature(v, s, "weighted")
    inside = ~np.isnan(h)
    assert inside.sum() > 0
    factor = (np.pi / n_around) / np.sin(np.pi / n_around)
    assert_allclose(h[inside], factor / (dim * r), rtol=1e-10)


# Area-weighted mean of H over the sphere (total mean curvature / area), relative
# error per subdivision level 0..3. Observed, weighted: n=2 0.508, 0.134, 0.034,
# 0.0085; n=3 0.814, 0.242, 0.063, 0.015 (second order: /4 per level).
# Laplace-Beltrami: below 0.0025 at every level (its total is nearly exact).
SPHERE_TOL = {
    ("weighted", 2): [0.52, 0.14, 0.036, 0.009],
    ("weighted", 3): [0.82, 0.25, 0.065, 0.016],
    ("laplace_beltrami", 2): [0.003] * 4,
    ("laplace_beltrami", 3): [0.003] * 4,
}


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("operator", ["weighted", "laplace_beltrami"])
def test_sphere_converges_to_one_over_r(dim, operator):
    r = 2.0
    for level, tol in enumerate(SPHERE_TOL[operator, dim]):
        v, s = tessellation.sphere(dim, r, level)
        h = vertex_curvature(v, s, operator)
        area = mesh.vertex_volumes(v, s)
        err = abs((h * area).sum() / area.sum() - 1 / r) * r
        assert err < tol, (level, err)
        assert (h > 0).all()  # outward normals: positive everywhere


def test_sphere_n2_pointwise_median_converges():
    # Pointwise convergence fails at the 6 irregular (valence-4) vertices of the
    # refined octahedron; the median vertex converges (tolerances per level 1..3).
    # Observed medians: weighted 0.045, 0.0056, 0.0044; Laplace-Beltrami 0.088, 0.028, 0.0074.
    tolerances = {"weighted": [0.05, 0.007, 0.005], "laplace_beltrami": [0.09, 0.03, 0.008]}
    for operator, tols in tolerances.items():
        for level, tol in zip([1, 2, 3], tols, strict=True):
            v, s = tessellation.sphere(2, 1.0, level)
            assert np.median(abs(vertex_curvature(v, s, operator) - 1)) < tol, (operator, level)


def test_graph_peak_is_positive_and_bowl_negative():
    # docs/design.md section 2: f = -0.4|x|^2 has H(0) = +0.8 (n = 3), f = +0.4|x|^2 has -0.8.
    for sign in (-1, 1):
        v, s = tessellation.kuhn_cube_mesh(
            33, lambda x, y, z, sign=sign: sign * 0.4 * (x * x + y * y + z * z))
        centre = np.argmin(np.linalg.norm(v[:, :3], axis=1))
        for operator in ORIENTED[::2]:
            assert_allclose(vertex_curvature(v, s, operator)[centre], -sign * 0.8, rtol=1e-2)


@pytest.mark.parametrize("operator", ["weighted", "laplace_beltrami"])
def test_kuhn_graph_converges_at_second_order(operator):
    f = FUNCTIONS["quadratic_sum"]
    errors = []
    resolutions = [9, 17, 33]
    for res in resolutions:
        v, s = tessellation.kuhn_cube_mesh(res, f)
        h = vertex_curvature(v, s, operator)
        inside = ~np.isnan(h)
        exact = f.mean_curvature(*v[inside, :3].T)
        errors.append(np.sqrt(np.mean((h[inside] - exact) ** 2)))
    h_step = 2.0 / (np.array(resolutions) - 1)
    slope = np.polyfit(np.log(h_step), np.log(errors), 1)[0]
    assert 1.9 < slope < 2.2, (slope, errors)


def test_n2_matches_trimesh_integral_mean_curvature():
    trimesh = pytest.importorskip("trimesh")
    v, s = tessellation.sphere(2, 1.0, 2)
    rng = np.random.default_rng(0)
    v = v * (1 + 0.05 * rng.standard_normal((len(v), 1)))  # a bumpy closed surface
    tm = trimesh.Trimesh(v, s, process=False)
    # Unweighted: trimesh's measure in a ball of radius rho (smaller than every edge
    # and every non-incident edge's distance) is rho/2 * sum of signed angles.
    rho = 1e-3
    measure = trimesh.curvature.discrete_mean_curvature_measure(tm, v, rho)
    assert_allclose(vertex_curvature(v, s, "unweighted"), 2 * measure / rho, atol=1e-9)
    # Weighted: H * 4 A_p = sum |e| psi, with trimesh's edges, angles and convexity.
    edges = tm.face_adjacency_edges
    signed = tm.face_adjacency_angles * np.where(tm.face_adjacency_convex, 1, -1)
    lengths = np.linalg.norm(v[edges[:, 0]] - v[edges[:, 1]], axis=1)
    integral = np.bincount(edges.ravel(), np.repeat(lengths * signed, 2), minlength=len(v))
    area = mesh.vertex_volumes(v, s)
    assert_allclose(vertex_curvature(v, s, "weighted") * 4 * area, integral, atol=1e-9)


def test_laplace_beltrami_weights_equal_libigl_cotmatrix_in_r4():
    igl = pytest.importorskip("igl")
    v, s = tessellation.kuhn_cube_mesh(5, FUNCTIONS["sine"])
    reference = igl.cotmatrix(v, s)
    assert_allclose((cotangent_weights(v, s) - reference).toarray(), 0, atol=1e-12)
    v2, s2 = tessellation.sphere(2, 1.0, 2)
    assert_allclose((cotangent_weights(v2, s2) - igl.cotmatrix(v2, s2)).toarray(), 0, atol=1e-12)


def test_laplace_beltrami_is_the_cotangent_formula():
    # K(p) = (1/|p|) sum_j w_pj (p - x_j) with the explicit weights, against the
    # gradient-of-volume accumulation vertex_curvature uses.
    v, s = tessellation.kuhn_cube_mesh(7, FUNCTIONS["exponential"])
    w = cotangent_weights(v, s)
    k = -(w @ v) / mesh.vertex_volumes(v, s)[:, None]
    normal = mesh.per_vertex_normals(v, s)
    h = np.sign(np.einsum("ij,ij->i", k, normal)) * np.linalg.norm(k, axis=1) / 3
    lb = vertex_curvature(v, s, "laplace_beltrami")
    inside = ~np.isnan(lb)
    assert_allclose(lb[inside], h[inside], rtol=1e-10, atol=1e-12)


def test_intrinsic_solid_angle_deficit_at_cube_corner_like_vertex():
    # Interior vertex of a flat Kuhn grid: the 24 solid angles fill 4 pi exactly.
    v, s = tessellation.kuhn_cube_mesh(3)
    assert_allclose(vertex_curvature(v, s, "intrinsic")[13], 0, atol=1e-12)
    # The unit 3-sphere's intrinsic distortion is positive (spherical: angle excess
    # is negative in the sum, deficit positive).
    vs, ss = tessellation.sphere(3, 1.0, 1)
    assert (vertex_curvature(vs, ss, "intrinsic") > 0).all()


@pytest.mark.parametrize("operator", ALL)
@pytest.mark.parametrize("scale", [0.5, 3.0])
def test_scaling_divides_curvature(operator, scale):
    v, s = tessellation.sphere(3, 1.0, 1)
    v = v * (1 + 0.1 * np.random.default_rng(1).random((len(v), 1)))
    h = vertex_curvature(v, s, operator)
    hs = vertex_curvature(scale * v, s, operator)
    if operator in ("unweighted", "intrinsic"):  # angles: scale-invariant
        assert_allclose(hs, h, rtol=1e-10, atol=1e-12)
    else:
        assert_allclose(hs, h / scale, rtol=1e-10)


@pytest.mark.parametrize("operator", ALL)
def test_rigid_motion_changes_nothing(operator, rng):
    v, s = tessellation.kuhn_cube_mesh(6, FUNCTIONS["cubic"])
    q, r = np.linalg.qr(rng.standard_normal((4, 4)))
    q = q * np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    moved = v @ q.T + rng.standard_normal(4)
    assert_allclose(vertex_curvature(moved, s, operator), vertex_curvature(v, s, operator),
                    rtol=1e-9, atol=1e-11)


@pytest.mark.parametrize("operator", ALL)
def test_reversing_orientation_flips_oriented_operators_only(operator):
    v, s = tessellation.kuhn_cube_mesh(6, FUNCTIONS["exponential"])
    reversed_s = s[:, [1, 0, 2, 3]]
    h, hr = vertex_curvature(v, s, operator), vertex_curvature(v, reversed_s, operator)
    expected = h if operator == "intrinsic" else -h
    assert_allclose(hr, expected, rtol=1e-12, atol=1e-14)


def test_bending_angles_sign_ridge_positive_valley_negative():
    # Two triangles over the unit square folded along the diagonal.
    for height, sign in [(-0.3, 1), (0.3, -1)]:
        # f at (1, 0) and (0, 1) is 0, at (0, 0) and (1, 1) equal height: a fold on
        # the diagonal (1,0)-(0,1); raising the far corners makes a valley.
        v = np.array([[0, 0, height], [1, 0, 0], [0, 1, 0], [1, 1, height]], float)
        s = np.array([[0, 1, 2], [1, 3, 2]])
        _, psi, measure = bending_angles(v, s)
        assert np.sign(psi[0]) == sign
        assert_allclose(measure, [np.sqrt(2)])


def test_bad_input_is_a_clear_error():
    v, s = tessellation.sphere(2, 1.0, 1)
    with pytest.raises(ValueError, match="unknown `operator`"):
        vertex_curvature(v, s, "gaussian")
    with pytest.raises(ValueError, match="unknown `boundary`"):
        vertex_curvature(v, s, boundary="zero")
    with pytest.raises(ValueError, match=r"must be \(S, 3\)"):
        vertex_curvature(v, s[:, :2])
    with pytest.raises(ValueError, match="outside `vertices`"):
        vertex_curvature(v, s + len(v))
    flat = v.copy()
    flat[s[3]] = flat[s[3][0]] + [[0, 0, 0], [1e-9, 0, 0], [2e-9, 0, 0]]
    with pytest.raises(ValueError, match="zero volume"):
        vertex_curvature(flat, s)
    with pytest.raises(ValueError, match="shared by 3 simplices"):
        vertex_curvature(np.eye(3)[[0, 1, 2, 0, 1]] + [[0, 0, 0]] * 5 + np.arange(5)[:, None] * 0.1,
                         [[0, 1, 2], [0, 1, 3], [0, 1, 4]])
    broken = s.copy()
    broken[0, [0, 1]] = broken[0, [1, 0]]
    with pytest.raises(ValueError, match="not consistently oriented"):
        vertex_curvature(v, broken)


def test_partial_boundary_gives_finite_values():
    v, s = tessellation.kuhn_cube_mesh(5, FUNCTIONS["quadratic_sum"])
    h = vertex_curvature(v, s, boundary="partial")
    assert np.isfinite(h).all()
