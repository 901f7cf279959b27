"""Validity of the three tessellations of [-1, 1]^3: Kuhn grid, irregular, diamond."""

import itertools

import numpy as np
import pytest

from volseg.analytic import FUNCTIONS
from volseg.mesh import faces, is_consistently_oriented, ring_average
from volseg.noise import add_normal_noise
from volseg.tessellation import dihedral_angles, kuhn_cube_mesh
from volseg.tessellation.diamond import decode, diamond_mesh, interpolation_error
from volseg.tessellation.irregular import irregular_cube_mesh, lift


def _signed_volumes(points, tetrahedra):
    p = np.asarray(points)[tetrahedra]
    return np.linalg.det(p[:, 1:] - p[:, :1]) / 6


def assert_valid_cube_tessellation(points, tetrahedra):
    """Volume 8, one orientation (upward: negative determinant), every interior
    triangle in two tetrahedra, every other triangle on the cube's surface."""
    volumes = _signed_volumes(points, tetrahedra)
    assert np.all(volumes < 0), "every tetrahedron is upward-oriented and non-degenerate"
    assert -volumes.sum() == pytest.approx(8.0, rel=1e-12)
    found = faces(tetrahedra, len(points))
    on_boundary = ~found.interior
    corners = np.asarray(points)[found.vertices[on_boundary]]  # (F, 3, 3)
    flat_on_a_side = np.zeros(len(corners), dtype=bool)
    for axis in range(3):
        for side in (-1.0, 1.0):
            flat_on_a_side |= np.all(np.isclose(corners[:, :, axis], side), axis=1)
    assert flat_on_a_side.all(), "a triangle in one tetrahedron only lies inside the cube"
    assert is_consistently_oriented(tetrahedra)


def test_kuhn_cube_mesh_is_valid():
    vertices, tetrahedra = kuhn_cube_mesh(5)
    assert_valid_cube_tessellation(vertices[:, :3], tetrahedra)


@pytest.mark.parametrize("n_vertices", [125, 1000])
def test_irregular_mesh_is_valid_seeded_and_reports_slivers(n_vertices):
    mesh = irregular_cube_mesh(n_vertices, seed=4)
    assert abs(len(mesh.points) - n_vertices) <= 0.02 * n_vertices
    assert_valid_cube_tessellation(mesh.points, mesh.tetrahedra)
    # Boundary samples sit on the surface (all 8 corners among them), the rest inside.
    on_surface = np.any(np.isclose(np.abs(mesh.points), 1.0), axis=1)
    np.testing.assert_array_equal(on_surface, mesh.boundary)
    for corner in itertools.product((-1.0, 1.0), repeat=3):
        assert np.any(np.all(mesh.points == corner, axis=1))
    again = irregular_cube_mesh(n_vertices, seed=4)
    np.testing.assert_array_equal(again.points, mesh.points)
    np.testing.assert_array_equal(again.tetrahedra, mesh.tetrahedra)
    assert not np.array_equal(irregular_cube_mesh(n_vertices, seed=5).points, mesh.points)
    angles = dihedral_angles(mesh.points, mesh.tetrahedra)
    np.testing.assert_allclose(angles.min(axis=1), mesh.min_dihedral)
    assert mesh.slivers == int(np.sum(mesh.min_dihedral < 5.0))


def test_irregular_smoothing_moves_only_interior_points():
    raw = irregular_cube_mesh(343, seed=2, smoothing_iterations=0)
    smooth = irregular_cube_mesh(343, seed=2)
    np.testing.assert_array_equal(raw.points[raw.boundary], smooth.points[smooth.boundary])
    assert not np.allclose(raw.points[~raw.boundary], smooth.points[~smooth.boundary])
    # Smoothing makes the sample spacing more even.
    assert np.median(smooth.min_dihedral) > np.median(raw.min_dihedral)


def test_dihedral_angles_of_the_kuhn_tetrahedron():
    # Class 0 of docs/design.md section 8: 45, 45, 60, 90, 90, 90 degrees.
    tet = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [1, 1, 1]], dtype=float)
    angles = np.sort(dihedral_angles(tet, np.array([[0, 1, 2, 3]]))[0])
    np.testing.assert_allclose(angles, [45, 45, 60, 90, 90, 90])


def test_diamond_decoding_matches_the_design_example():
    root = decode((2, 2, 2), 4)
    assert root.kind == 0 and root.parents() == [] and len(root.tetrahedra()) == 6
    face = decode((2, 2, 0), 4)
    assert face.kind == 1 and set(face.spine) == {(0, 0, 0), (4, 4, 0)}
    assert face.parents() == [(2, 2, 2)] and len(face.tetrahedra()) == 2
    edge = decode((2, 0, 0), 4)
    assert edge.kind == 2 and set(edge.spine) == {(0, 0, 0), (4, 0, 0)}
    assert sorted(edge.parents()) == [(2, 0, 2), (2, 2, 0)]
    assert sorted(edge.children()) == [(1, 1, 1), (3, 1, 1)]
    with pytest.raises(ValueError, match="corner"):
        decode((0, 4, 0), 4)


def test_every_grid_point_but_the_corners_is_one_diamond_and_shapes_are_three():
    n = 8
    shapes = set()
    for v in itertools.product(range(n + 1), repeat=3):
        if all(c in (0, n) for c in v):
            continue
        d = decode(v, n)
        p0, p1 = np.array(d.spine)
        np.testing.assert_array_equal((p0 + p1) // 2, v)  # the centre halves the spine
        for tet in d.tetrahedra():
            angles = dihedral_angles(np.array(tet, float), np.array([[0, 1, 2, 3]]))[0]
            shapes.add(tuple(np.round(np.sort(angles)).astype(int)))
    assert shapes == {(45, 45, 60, 90, 90, 90), (45, 45, 60, 60, 90, 120),
                      (45, 60, 60, 90, 90, 90)}


@pytest.mark.parametrize("n", [4, 8])
def test_full_resolution_diamond_mesh_is_the_reflected_kuhn_grid(n):
    mesh = diamond_mesh(np.zeros((n + 1,) * 3), -1.0)
    assert len(mesh.tetrahedra) == 6 * n**3 and len(mesh.grid) == (n + 1) ** 3
    assert_valid_cube_tessellation(mesh.points, mesh.tetrahedra)
    corners = mesh.grid[mesh.tetrahedra]  # (T, 4, 3)
    lo = corners.min(axis=1)
    # Each tetrahedron is a monotone path across one unit cell, between its all-even
    # and all-odd corners.
    assert np.all(corners.max(axis=1) - lo == 1)
    for tet in corners:
        diagonal = [p for p in tet if np.all(p % 2 == 0) or np.all(p % 2 == 1)]
        assert len(diagonal) == 2
    valence = np.bincount(mesh.tetrahedra.ravel())
    interior = np.all((mesh.grid > 0) & (mesh.grid < n), axis=1)
    all_same = np.all(mesh.grid % 2 == mesh.grid[:, :1] % 2, axis=1)
    assert set(valence[interior & all_same]) == {48}
    assert set(valence[interior & ~all_same]) == {16}


def _hanging_vertices(mesh):
    """Mesh vertices lying inside or on a tetrahedron without being its corner."""
    vertex_set = {tuple(p) for p in mesh.grid}
    bad = 0
    for tet in mesh.grid[mesh.tetrahedra]:
        c = tet.astype(float)
        inverse = np.linalg.inv((c[1:] - c[0]).T)
        lo, hi = tet.min(axis=0), tet.max(axis=0)
        for p in itertools.product(*[range(lo[i], hi[i] + 1) for i in range(3)]):
            if p not in vertex_set or any(np.array_equal(p, q) for q in tet):
                continue
            b = inverse @ (np.array(p) - c[0])
            if b.min() >= -1e-9 and b.sum() <= 1 + 1e-9:
                bad += 1
    return bad


@pytest.mark.parametrize("name", ["exponential", "sine"])
def test_adaptive_diamond_mesh_is_conforming_and_holds_its_error_bound(name):
    n = 16
    axis = np.linspace(-1, 1, n + 1)
    values = FUNCTIONS[name](*np.meshgrid(axis, axis, axis, indexing="ij"))
    eps = 0.02 * np.ptp(values)
    mesh = diamond_mesh(values, eps)
    assert 50 < len(mesh.grid) < (n + 1) ** 3  # adaptive: neither the root nor everything
    assert_valid_cube_tessellation(mesh.points, mesh.tetrahedra)
    assert _hanging_vertices(mesh) == 0
    assert interpolation_error(values, mesh.grid[mesh.tetrahedra]) <= eps
    # A looser bound gives a coarser mesh.
    assert len(diamond_mesh(values, 4 * eps).grid) < len(mesh.grid)


def test_diamond_mesh_refuses_a_grid_that_is_not_2k_plus_1():
    with pytest.raises(ValueError, match="2\\^k"):
        diamond_mesh(np.zeros((10, 10, 10)), 0.1)


def test_ring_average_keeps_constants_and_nans_and_averages_the_1_ring():
    vertices, tetrahedra = kuhn_cube_mesh(4)
    constant = np.full(len(vertices), 3.0)
    constant[0] = np.nan
    out = ring_average(constant, tetrahedra, 5)
    assert np.isnan(out[0]) and np.allclose(out[1:], 3.0)
    spike = np.zeros(len(vertices))
    centre = np.ravel_multi_index((1, 1, 1), (4, 4, 4))
    spike[centre] = 15.0
    once = ring_average(spike, tetrahedra, 1)
    assert once[centre] == pytest.approx(1.0)  # 15 over itself and its 14 neighbours
    assert np.count_nonzero(once) == 15


def test_normal_noise_moves_along_normals_by_the_asked_amount():
    vertices, tetrahedra = kuhn_cube_mesh(9, lambda x, y, z: 0 * x)
    moved = add_normal_noise(vertices, tetrahedra, 10.0, seed=1)
    shift = moved - vertices
    np.testing.assert_allclose(shift[:, :3], 0, atol=1e-12)  # flat graph: normal is e4
    assert shift[:, 3].std() == pytest.approx(0.1 * _mean_edge(vertices, tetrahedra), rel=0.1)
    np.testing.assert_array_equal(add_normal_noise(vertices, tetrahedra, 10.0, seed=1), moved)
    assert np.array_equal(add_normal_noise(vertices, tetrahedra, 0.0, seed=1), vertices)
    still = np.zeros(len(vertices), bool)
    still[:10] = True
    partly = add_normal_noise(vertices, tetrahedra, 10.0, seed=1, movable=~still)
    np.testing.assert_array_equal(partly[still], vertices[still])


def _mean_edge(vertices, tetrahedra):
    pairs = np.concatenate([tetrahedra[:, [i, j]] for i, j in itertools.combinations(range(4), 2)])
    pairs = np.unique(np.sort(pairs, axis=1), axis=0)
    return np.linalg.norm(vertices[pairs[:, 0]] - vertices[pairs[:, 1]], axis=1).mean()


def test_lift_puts_the_function_in_the_fourth_coordinate():
    points = np.array([[0.0, 0.5, -1.0], [1.0, 1.0, 1.0]])
    f = FUNCTIONS["quadratic_sum"]
    np.testing.assert_allclose(lift(points, f)[:, 3], f(*points.T))


def test_the_meshes_minimum_dihedral_is_that_of_dihedral_angles():
    mesh = irregular_cube_mesh(200, seed=1)
    angles = dihedral_angles(mesh.points, mesh.tetrahedra)
    np.testing.assert_allclose(angles.min(axis=1), mesh.min_dihedral, atol=1e-9)
