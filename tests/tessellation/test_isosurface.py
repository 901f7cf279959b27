"""Isosurfaces on the Kuhn triangulation (docs/design.md section 11): exact small cases in
2-D and 3-D, the 3-sphere in R^4, ties, boundaries, and the mesh-quality option."""

import itertools
import math

import numpy as np
import pytest

from volseg import mesh, vertex_curvature
from volseg.tessellation import isosurface, level_set, quality, relax_isosurface

from ..conftest import smooth_random_field


def ball_field(d, n, lo=-1.0, hi=1.0):
    axis = np.linspace(lo, hi, n)
    points = np.meshgrid(*[axis] * d, indexing="ij")
    return -sum(p ** 2 for p in points), axis[1] - axis[0]


def euler_characteristic(simplices):
    """V - E + F - ... from the distinct faces of every size (int64 keys)."""
    k = simplices.shape[1]
    base = int(simplices.max()) + 1
    total = 0
    for size in range(1, k + 1):
        assert base ** min(size, k - 1) < 2 ** 62
        sub = np.sort(np.concatenate([simplices[:, list(c)]
                                      for c in itertools.combinations(range(k), size)]), axis=1)
        keys = (sub @ (base ** np.arange(size, dtype=np.int64)) if size < k
                else np.arange(len(simplices)))
        total += (-1) ** (size - 1) * len(np.unique(keys))
    return total


def assert_closed_oriented_outward(surface):
    f = mesh.faces(surface.simplices, len(surface.vertices))   # raises on a non-manifold face
    assert f.interior.all() and len(surface.boundary_faces) == 0
    assert f.consistent.all()
    normals = mesh.simplex_normals(surface.vertices, surface.simplices)
    centres = surface.vertices[surface.simplices].mean(axis=1)
    assert (np.einsum("ij,ij->i", normals, centres) > 0).all()   # outward: toward lower F
    assert len(mesh.pinched_vertices(surface.simplices, len(surface.vertices))) == 0


def test_circle_is_a_closed_counter_clockwise_polygon():
    field, h = ball_field(2, 41)
    surface = isosurface(field, -0.6 ** 2, spacing=h, origin=(-1, -1))
    assert surface.simplices.shape[1] == 2
    assert_closed_oriented_outward(surface)
    # Each vertex starts one segment and ends one: a cycle, walked counter-clockwise.
    every = list(range(len(surface.vertices)))
    assert sorted(surface.simplices[:, 0]) == sorted(surface.simplices[:, 1]) == every
    x, y = surface.vertices[surface.simplices[:, 0]].T
    x2, y2 = surface.vertices[surface.simplices[:, 1]].T
    assert 0.5 * np.sum(x * y2 - x2 * y) > 0          # positive signed area
    length = mesh.simplex_volumes(surface.vertices, surface.simplices).sum()
    assert length == pytest.approx(2 * math.pi * 0.6, rel=2e-3)
    assert euler_characteristic(surface.simplices) == 0


def test_sphere_matches_scikit_image_marching_cubes():
    from skimage.measure import marching_cubes, mesh_surface_area

    field, h = ball_field(3, 31)
    surface = isosurface(field, -0.7 ** 2, spacing=h, origin=(-1, -1, -1))
    assert_closed_oriented_outward(surface)
    assert euler_characteristic(surface.simplices) == 2
    area = mesh.simplex_volumes(surface.vertices, surface.simplices).sum()
    verts, faces, _, _ = marching_cubes(field, -0.7 ** 2, spacing=(h, h, h))
    # Both interpolate linearly along grid edges; measured: equal to 1e-7.
    assert area == pytest.approx(mesh_surface_area(verts, faces), rel=1e-5)
    assert area == pytest.approx(4 * math.pi * 0.49, rel=0.01)


@pytest.mark.slow
def test_three_sphere_in_r4_is_closed_oriented_and_has_the_right_volume():
    r = 0.6
    field, h = ball_field(4, 33)
    surface = isosurface(field, -r * r, spacing=h, origin=(-1,) * 4)
    assert surface.vertices.shape[1] == 4 and surface.simplices.shape[1] == 4
    assert_closed_oriented_outward(surface)
    assert euler_characteristic(surface.simplices) == 0
    volume = mesh.simplex_volumes(surface.vertices, surface.simplices).sum()
    assert volume == pytest.approx(2 * math.pi ** 2 * r ** 3, rel=0.01)   # measured -0.95 %
    # Vertices lie on the level set of the interpolant: on the sphere to O(h^2).
    radius = np.linalg.norm(surface.vertices, axis=1)
    assert np.abs(radius - r).max() < h ** 2


@pytest.mark.slow
def test_relaxation_makes_the_three_sphere_curvature_right():
    r = 0.6
    field, h = ball_field(4, 17)
    raw = isosurface(field, -r * r, spacing=h, origin=(-1,) * 4)
    relaxed = relax_isosurface(raw, field, -r * r, spacing=h, origin=(-1,) * 4, iterations=10)
    before = vertex_curvature(raw.vertices, raw.simplices, "weighted") * r
    after = vertex_curvature(relaxed.vertices, relaxed.simplices, "weighted") * r
    # Measured: median H r 1.099 raw (slivers), 1.005 relaxed; RMS error 9.8 -> 0.40.
    assert abs(np.median(before) - 1) > 0.05
    assert np.median(after) == pytest.approx(1.0, abs=0.02)
    assert np.sqrt(np.mean((after - 1) ** 2)) < 0.6
    assert np.abs(np.linalg.norm(relaxed.vertices, axis=1) - r).max() < 1e-3   # still on it
    assert_closed_oriented_outward(relaxed)
    assert (quality(relaxed.vertices, relaxed.simplices)["min"] > 10
            > quality(raw.vertices, raw.simplices)["min"])


def test_planes_through_the_box_have_boundary_and_zero_curvature():
    axis = np.linspace(0, 1, 9)
    x, y, z = np.meshgrid(axis, axis, axis, indexing="ij")
    surface = isosurface(0.37 - x + 0 * y, 0.0, spacing=1 / 8)
    assert len(surface.boundary_faces) > 0
    assert np.allclose(surface.vertices[:, 0], 0.37)
    normals = mesh.simplex_normals(surface.vertices, surface.simplices)
    assert np.allclose(normals, [1, 0, 0])                         # toward lower values
    boundary = np.unique(surface.boundary_faces)
    ends = surface.vertices[boundary][:, 1:]
    on_box = np.isclose(ends, 0) | np.isclose(ends, 1)
    assert on_box.any(axis=1).all()
    curvature = vertex_curvature(surface.vertices, surface.simplices, boundary="partial")
    assert np.allclose(curvature, 0, atol=1e-12)


@pytest.mark.parametrize("d", [2, 3, 4])
def test_random_fields_give_conforming_consistently_oriented_manifolds(d, rng):
    shape = {2: (40, 40), 3: (16, 16, 16), 4: (8, 8, 8, 8)}[d]
    field = smooth_random_field(shape, rng, sigma=1.5)
    surface = isosurface(field, 0.0)
    f = mesh.faces(surface.simplices, len(surface.vertices))
    assert f.consistent.all()
    assert len(mesh.pinched_vertices(surface.simplices, len(surface.vertices))) == 0
    assert (mesh.simplex_volumes(surface.vertices, surface.simplices) > 0).all()
    # Boundary faces lie on the grid's boundary, nowhere else.
    points = surface.vertices[surface.boundary_faces]
    on = ((np.isclose(points, 0) | np.isclose(points, np.array(shape) - 1)).all(axis=1)).any(axis=1)
    assert on.all()
    # Normals point toward lower values: compare with the sampled gradient.
    gradient = np.stack(np.gradient(field), axis=-1)
    centre = np.rint(surface.vertices[surface.simplices].mean(axis=1)).astype(int)
    g = gradient[tuple(centre.T)]
    normals = mesh.simplex_normals(surface.vertices, surface.simplices)
    assert (np.einsum("ij,ij->i", normals, g) < 0).mean() > 0.97


def test_samples_exactly_at_the_level_give_no_flat_simplices(rng):
    field = rng.integers(0, 5, size=(12, 12, 12)).astype(np.uint8)
    surface = isosurface(field, 2)
    assert (field == 2).any()
    f = mesh.faces(surface.simplices, len(surface.vertices))
    assert f.consistent.all()
    assert (mesh.simplex_volumes(surface.vertices, surface.simplices) > 1e-12).all()
    merged = surface.edges[:, 0] == surface.edges[:, 1]
    assert merged.any() and (field.ravel()[surface.edges[merged, 0]] == 2).all()
    assert len(np.unique(surface.simplices)) == len(surface.vertices)   # no orphan vertices


def test_spacing_and_origin_scale_and_move_the_surface():
    field, _ = ball_field(3, 15)
    unit = isosurface(field, -0.5)
    moved = isosurface(field, -0.5, spacing=(2.0, 3.0, 0.5), origin=(1.0, -1.0, 4.0))
    assert np.array_equal(unit.simplices, moved.simplices)
    assert np.allclose(moved.vertices, unit.vertices * [2.0, 3.0, 0.5] + [1.0, -1.0, 4.0])


def test_level_set_slices_a_mesh():
    from volseg.tessellation import sphere

    vertices, triangles = sphere(2, radius=1.0, subdivisions=3)
    equator = level_set(vertices, triangles, vertices[:, 2], 0.0, oriented=False)
    assert equator.simplices.shape[1] == 2
    assert np.allclose(equator.vertices[:, 2], 0)
    assert np.allclose(np.linalg.norm(equator.vertices, axis=1), 1, atol=0.05)
    counts = np.bincount(equator.simplices.ravel())
    assert (counts == 2).all()                                   # a closed cycle


def test_level_not_crossed_gives_an_empty_surface():
    field, _ = ball_field(3, 9)
    surface = isosurface(field, 5.0)
    assert surface.vertices.shape == (0, 3) and surface.simplices.shape == (0, 3)


@pytest.mark.parametrize("field, level, kwargs, message", [
    (np.zeros(5), 0.0, {}, "2 or more axes"),
    (np.zeros((1, 5)), 0.0, {}, "2 or more axes"),
    (np.full((3, 3), np.nan), 0.0, {}, "NaN or infinite"),
    (np.zeros((3, 3)), float("nan"), {}, "`level` must be a finite number"),
    (np.zeros((3, 3)), "high", {}, "`level` must be a finite number"),
    (np.zeros((3, 3)), 0.0, {"spacing": (1.0, -1.0)}, "`spacing` must be 2 positive"),
    (np.zeros((3, 3)), 0.0, {"snap": 0.5}, "`snap` must be in"),
    (np.array([["a", "b"], ["c", "d"]]), 0.0, {}, "numeric"),
])
def test_bad_arguments_are_named(field, level, kwargs, message):
    with pytest.raises(ValueError, match=message):
        isosurface(field, level, **kwargs)


@pytest.mark.parametrize("shape", [(9, 8, 7), (7, 6, 6, 5)])
def test_relaxation_spline_interpolates_and_has_its_exact_gradient(shape, rng):
    """The compiled cubic spline (the generic kernel in 3-D, the 4-D one in 4-D): equal to
    the samples at grid points, its gradient equal to its own central differences."""
    from volseg.tessellation.mesh_quality import _Spline

    field = rng.standard_normal(shape)
    spacing = np.linspace(0.5, 1.5, len(shape))
    spline = _Spline(field, spacing, np.zeros(len(shape)))
    grid = np.stack(np.meshgrid(*[np.arange(n) for n in shape], indexing="ij"), -1)
    grid = grid.reshape(-1, len(shape))
    values, _ = spline.value_and_gradient(grid * spacing)
    assert np.allclose(values, field.ravel(), atol=1e-12)
    points = rng.uniform(0.5, min(shape) - 1.5, (40, len(shape))) * spacing
    _, gradient = spline.value_and_gradient(points)
    step = 1e-6
    def value(p):
        return spline.value_and_gradient(p)[0]

    differences = np.stack([(value(points + step * e) - value(points - step * e)) / (2 * step)
                            for e in np.eye(len(shape))], axis=1)
    assert np.allclose(gradient, differences, atol=1e-6)
