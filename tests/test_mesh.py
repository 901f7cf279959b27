import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from volseg import mesh, tessellation


def test_simplex_volumes_of_unit_simplices_any_codimension():
    # A unit right triangle lifted into R^4 and a unit tetrahedron in R^4.
    v = np.array([[0, 0, 0, 0], [1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0]], float)
    assert_allclose(mesh.simplex_volumes(v, [[0, 1, 2]]), [0.5])
    assert_allclose(mesh.simplex_volumes(v, [[0, 1, 2, 3]]), [1 / 6])
    assert_allclose(mesh.simplex_volumes(v, [[0, 1]]), [1.0])


def test_faces_pair_interior_and_mark_boundary():
    v, s = tessellation.kuhn_grid_mesh(np.zeros((3, 3, 3)))
    f = mesh.faces(s)
    # 8 cubes x 12 triangles each, shared ones once: interior triangles have 2 tets.
    n_boundary = (~f.interior).sum()
    assert n_boundary == 6 * 4 * 2  # 6 sides x 4 squares x 2 triangles
    assert (f.simplices[f.interior] >= 0).all()
    assert f.consistent.all()
    boundary = mesh.boundary_vertices(s)
    assert_array_equal(np.flatnonzero(~boundary), [13])  # the centre of the 3x3x3 grid


def test_kuhn_grid_has_14_neighbours_24_tets_36_triangles_at_interior_vertex():
    _, s = tessellation.kuhn_grid_mesh(np.zeros((3, 3, 3)))
    centre = 13
    assert (s == centre).any(axis=1).sum() == 24
    f = mesh.faces(s)
    assert (f.vertices == centre).any(axis=1).sum() == 36
    neighbours = np.unique(s[(s == centre).any(axis=1)])
    assert len(neighbours) - 1 == 14


def test_kuhn_grid_normals_point_up_and_volumes_sum_to_the_box():
    v, s = tessellation.kuhn_grid_mesh(np.zeros((4, 3, 5)), spacing=(0.5, 1.0, 2.0))
    assert (mesh.simplex_normals(v, s)[:, 3] > 0).all()
    assert_allclose(mesh.simplex_volumes(v, s).sum(), 1.5 * 2.0 * 8.0)


def test_cross_product_is_the_n2_normal():
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float)
    assert_allclose(mesh.simplex_normals(v, [[0, 1, 2]]), [[0, 0, 1]])


@pytest.mark.parametrize("dim", [1, 2, 3])
def test_orient_repairs_random_flips(dim, rng):
    v, s = tessellation.sphere(dim, 1.0, 1)
    flip = rng.random(len(s)) < 0.5
    flip[0] = False
    broken = s.copy()
    broken[flip, 0], broken[flip, 1] = s[flip, 1], s[flip, 0]
    assert not mesh.is_consistently_oriented(broken)
    repaired = mesh.orient(broken)
    assert mesh.is_consistently_oriented(repaired)
    assert_array_equal(np.sort(repaired, axis=1), np.sort(s, axis=1))
    # The first simplex keeps its orientation, so the whole sphere is outward again.
    assert_array_equal(repaired, s)
    assert_array_equal(broken[flip], s[flip][:, [1, 0] + list(range(2, dim + 1))])


def test_orient_refuses_a_moebius_band():
    n = 6
    tri = []
    for i in range(n):
        a, b = i, (i + 1) % n
        # Top and bottom rows swap at the seam: vertex i (top), i + n (bottom).
        top_a, bot_a = a, a + n
        top_b, bot_b = (b, b + n) if b else (n, 0)
        tri += [[top_a, bot_a, top_b], [bot_a, bot_b, top_b]]
    with pytest.raises(ValueError, match="not orientable"):
        mesh.orient(np.array(tri))


def test_face_shared_by_three_simplices_is_named():
    s = np.array([[0, 1, 2], [0, 1, 3], [0, 1, 4]])
    with pytest.raises(ValueError, match=r"face \[0, 1\] is shared by 3 simplices \[0, 1, 2\]"):
        mesh.faces(s)


def test_check_mesh_errors_name_the_problem():
    v = np.zeros((4, 3))
    with pytest.raises(ValueError, match=r"`simplices` must be \(S, 3\) for vertices in R\^3"):
        mesh.check_mesh(v, [[0, 1, 2, 3]])
    with pytest.raises(ValueError, match="outside `vertices`"):
        mesh.check_mesh(v, [[0, 1, 7]])
    with pytest.raises(ValueError, match="repeat a vertex"):
        mesh.check_mesh(v, [[0, 1, 1]])
    with pytest.raises(ValueError, match=r"`vertices` must be a \(V, d\) array"):
        mesh.check_mesh(np.zeros(4), [[0, 1, 2]])
    bad = v.copy()
    bad[2, 1] = np.nan
    with pytest.raises(ValueError, match="non-finite coordinates \\(first at vertex 2\\)"):
        mesh.check_mesh(bad, [[0, 1, 2]])


def test_mesh_functions_do_not_modify_inputs():
    v, s = tessellation.sphere(2, 1.0, 1)
    v0, s0 = v.copy(), s.copy()
    mesh.orient(s)
    mesh.per_vertex_normals(v, s)
    mesh.vertex_volumes(v, s)
    assert_array_equal(v, v0)
    assert_array_equal(s, s0)


def test_pinched_vertex_and_empty_mesh_are_refused():
    from volseg import tessellation, vertex_curvature
    from volseg.mesh import pinched_vertices

    v, s = tessellation.sphere(dim=3, radius=1.0, subdivisions=1)
    assert len(pinched_vertices(s)) == 0
    # A second sphere, reflected through vertex 0 and sharing it: two 3-spheres touching.
    s2 = s + len(v)
    s2[s2 == len(v)] = 0
    vertices = np.concatenate([v, 2 * v[0] - v])
    simplices = np.concatenate([s, s2[:, [1, 0, 2, 3]]])
    assert pinched_vertices(simplices, len(vertices)).tolist() == [0]
    for operator in ["weighted", "laplace_beltrami", "intrinsic"]:
        with pytest.raises(ValueError, match="1 vertices are pinched .* vertex 0"):
            vertex_curvature(vertices, simplices, operator)
    with pytest.raises(ValueError, match="no simplices"):
        vertex_curvature(np.zeros((0, 4)), np.zeros((0, 4), int))
