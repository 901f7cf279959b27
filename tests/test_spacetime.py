"""Time-varying volumes as 3-manifolds in R^4: segment_mesh, segment_series, the exact
time slices, the series reader, and `volseg isosurface` / `volseg demo --time`."""

import json

import meshio
import nibabel
import numpy as np
import pytest

from volseg import mesh, segment_mesh
from volseg.cli import main
from volseg.datasets import demo_series
from volseg.io.series import read_series
from volseg.spacetime import segment_series, time_slices
from volseg.tessellation import isosurface, sphere


def moving_blob(n=12, steps=6, speed=0.06):
    """A Gaussian blob moving along x: its isosurface is a tube in space-time."""
    axis = np.linspace(-1, 1, n)
    x, y, z = np.meshgrid(axis, axis, axis, indexing="ij")
    return np.stack([np.exp(-((x - speed * t) ** 2 + y ** 2 + z ** 2) / 0.3)
                     for t in range(steps)], axis=-1)


def canonical(triangles):
    """A set of triangles given by their corner points, independent of order."""
    return {tuple(sorted(tuple(np.round(p, 9)) for p in tri)) for tri in triangles}


def test_segment_mesh_on_a_sphere_and_on_a_bumpy_sphere():
    vertices, triangles = sphere(2, radius=2.0, subdivisions=3)
    result = segment_mesh(vertices, triangles, n_regions=1)
    assert np.allclose(np.median(result.curvature), 0.5, rtol=0.02)   # 1/r
    assert (result.labels == 1).all()
    assert np.array_equal(result.vertices, vertices) and np.array_equal(result.simplices, triangles)
    # Two bumps -> two maxima of curvature that persist; two regions split between them.
    direction = vertices / np.linalg.norm(vertices, axis=1, keepdims=True)
    bump = 1 + 0.3 * (np.exp(-8 * ((direction - [0, 0, 1]) ** 2).sum(1))
                      + np.exp(-8 * ((direction + [0, 0, 1]) ** 2).sum(1)))
    result = segment_mesh(direction * bump[:, None], triangles, n_regions=2, smooth_rounds=3)
    top, bottom = np.argmax(direction[:, 2]), np.argmin(direction[:, 2])
    assert result.n_regions == 2 and result.labels[top] != result.labels[bottom]
    table = result.region_table()
    assert {row["maximum"] for row in table} <= set(range(len(vertices)))
    assert all(len(row["position"]) == 3 for row in table)


def test_segment_mesh_boundary_rules():
    vertices, triangles = sphere(2, radius=1.0, subdivisions=2)
    cap = triangles[(vertices[triangles][:, :, 2] > -0.2).all(axis=1)]   # an open cap
    partial = segment_mesh(vertices, cap, n_regions=1)
    left_out = segment_mesh(vertices, cap, n_regions=1, boundary="nan")
    edge = mesh.boundary_vertices(cap, len(vertices))
    used = np.zeros(len(vertices), bool)
    used[cap.ravel()] = True
    assert np.isfinite(partial.curvature[used]).all()
    assert (left_out.labels[edge] == 0).all() and np.isnan(left_out.curvature[edge]).all()
    assert (left_out.labels[used & ~edge] == 1).all()
    assert left_out.mask.voxels == int((used & ~edge).sum())
    with pytest.raises(ValueError, match="boundary"):
        segment_mesh(vertices, cap, boundary="clamp")


def test_time_slices_are_the_isosurfaces_of_the_time_steps():
    field = moving_blob()
    surface = isosurface(field, 0.5, spacing=(0.2, 0.2, 0.2, 0.5))
    for piece in time_slices(surface, field.shape):
        alone = isosurface(field[..., piece.step], 0.5, spacing=0.2)
        points = surface.vertices[piece.vertex]
        assert np.allclose(points[:, 3], 0.5 * piece.step)              # in the step's hyperplane
        # The same triangles as the step's own 3-D isosurface.
        assert (canonical(points[piece.triangles][..., :3])
                == canonical(alone.vertices[alone.simplices]))


def test_segment_series_moving_blob_relaxed_slices_stay_in_their_steps():
    field = moving_blob()
    result = segment_series(field, 0.5, spacing=(0.2, 0.2, 0.2), time_scale=0.5, relax=3,
                            n_regions=2)
    surface = result.surface
    f = mesh.faces(surface.simplices, len(surface.vertices))
    assert f.consistent.all() and len(surface.boundary_faces) > 0   # open at t = 0 and t = end
    for piece in result.slices():
        assert np.allclose(surface.vertices[piece.vertex, 3], 0.5 * piece.step)
        assert len(piece.triangles) > 0
    assert result.segmentation.n_regions == 2
    assert result.quality["relaxed"]["p1"] > result.quality["raw"]["p1"]
    assert np.isfinite(result.segmentation.curvature).all()


def test_segment_series_refuses_bad_input():
    field = moving_blob(n=6, steps=3)
    with pytest.raises(ValueError, match="must be 4-D"):
        segment_series(field[..., 0], 0.5)
    with pytest.raises(ValueError, match="not crossed"):
        segment_series(field, 5.0)
    with pytest.raises(ValueError, match="time_scale"):
        segment_series(field, 0.5, time_scale=0)


def test_read_series_from_one_4d_file_and_from_3d_steps(tmp_path):
    field = moving_blob(n=6, steps=3).astype(np.float32)
    np.save(tmp_path / "blob.npy", field)
    series = read_series(tmp_path / "blob.npy")
    assert series.shape == field.shape and np.array_equal(series.data, field)
    nibabel.save(nibabel.Nifti1Image(field, np.diag([0.5, 0.5, 0.5, 1])), tmp_path / "blob.nii.gz")
    series = read_series(tmp_path / "blob.nii.gz")
    assert series.shape == field.shape and series.spacing == (0.5, 0.5, 0.5)
    for t in range(3):
        np.save(tmp_path / f"step_{t}.npy", field[..., t])
    import zarr

    store = zarr.create_array(str(tmp_path / "blob.zarr"), shape=field.shape, chunks=(3, 3, 3, 3),
                              dtype="float32")
    store[:] = field
    assert np.array_equal(read_series(tmp_path / "blob.zarr").data, field)
    series = read_series(str(tmp_path / "step_*.npy"))
    assert np.array_equal(series.data, field) and len(series.files) == 3
    np.save(tmp_path / "step_9.npy", field[:5, ..., 0])
    with pytest.raises(ValueError, match="same shape"):
        read_series(str(tmp_path / "step_*.npy"))
    with pytest.raises(ValueError, match="must be 4-D"):
        read_series(tmp_path / "step_0.npy")
    with pytest.raises(FileNotFoundError):
        read_series(str(tmp_path / "nothing_*.npy"))


def test_series_steps_must_share_type_and_grid(tmp_path):
    """Issue 57 (#13): a float 0..1 step and a uint8 0..100 step were stacked as one
    float64 series (one field on one scale); steps at other origins were accepted.
    Both are refused naming the step."""
    field = moving_blob(n=6, steps=2).astype(np.float32)
    field = field / field.max()
    np.save(tmp_path / "s_0.npy", field[..., 0])
    np.save(tmp_path / "s_1.npy", np.round(field[..., 1] * 100).astype(np.uint8))
    with pytest.raises(ValueError, match=r"s_1.npy: a time step of type uint8, but .*float32"):
        read_series(str(tmp_path / "s_*.npy"))
    for t, origin in enumerate((0.0, 3.0)):
        affine = np.diag([0.5, 0.5, 0.5, 1.0])
        affine[0, 3] = origin
        nibabel.save(nibabel.Nifti1Image(field[..., t], affine), tmp_path / f"n_{t}.nii.gz")
    with pytest.raises(ValueError, match=r"n_1.nii.gz: its voxels sit elsewhere"):
        read_series(str(tmp_path / "n_*.nii.gz"))


def test_cli_isosurface_writes_a_paraview_series(tmp_path, capsys):
    field = moving_blob(n=10, steps=4)
    np.save(tmp_path / "blob.npy", field)
    out = tmp_path / "out"
    argv = ["isosurface", str(tmp_path / "blob.npy"), "--level", "0.5", "--regions", "3",
            "--relax", "2", "--time-scale", "2", "-o", str(out), "-q", "--json"]
    assert main(argv) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary == json.loads((out / "blob_iso_summary.json").read_text())
    assert summary["n_regions"] == 3 and summary["shape"] == [10, 10, 10, 4]
    saved = np.load(out / "blob_iso.npz")
    assert saved["vertices"].shape[1] == 4 and saved["tetrahedra"].shape[1] == 4
    assert set(np.unique(saved["labels"])) == {1, 2, 3}
    pvd = (out / "blob_iso.pvd").read_text()
    for t in range(4):
        assert f'file="blob_iso_t{t:04d}.vtu"' in pvd
        step = meshio.read(out / f"blob_iso_t{t:04d}.vtu")
        assert step.points.shape[1] == 3 and len(step.cells_dict["triangle"]) > 0
        assert set(step.point_data) == {"curvature", "labels", "vertex", "Normals"}
        assert np.array_equal(step.point_data["labels"], saved["labels"][step.point_data["vertex"]])
    assert (out / "blob_iso_preview.png").stat().st_size > 10_000
    # Existing outputs are refused, nothing changes.
    before = sorted(p.name for p in out.iterdir())
    assert main(argv) == 2
    assert "exist" in capsys.readouterr().err
    assert sorted(p.name for p in out.iterdir()) == before


@pytest.mark.parametrize("extra, message", [
    (["--level", "7"], "is not crossed"),
    (["--level", "0.5", "--time-scale", "0"], "`--time-scale` must be a positive number"),
    (["--level", "0.5", "--relax", "-1"], "numbers of rounds"),
    (["--level", "nan"], "--level must be a finite number"),
])
def test_cli_isosurface_bad_arguments_exit_2(tmp_path, capsys, extra, message):
    np.save(tmp_path / "blob.npy", moving_blob(n=6, steps=3))
    out = tmp_path / "out"
    assert main(["isosurface", str(tmp_path / "blob.npy"), "-o", str(out), *extra]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
    assert not out.exists() or not list(out.iterdir())


def test_cli_isosurface_refuses_a_3d_file(tmp_path, capsys):
    np.save(tmp_path / "one.npy", moving_blob(n=6, steps=3)[..., 0])
    assert main(["isosurface", str(tmp_path / "one.npy"), "--level", "0.5", "-o",
                 str(tmp_path / "out")]) == 2
    assert "must be 4-D" in capsys.readouterr().err


@pytest.mark.slow
def test_demo_time_follows_the_two_blobs(tmp_path, capsys):
    assert main(["demo", "--time", "-o", str(tmp_path), "-q"]) == 0
    assert "two blobs merging" in capsys.readouterr().out
    summary = json.loads((tmp_path / "demo_time_iso_summary.json").read_text())
    steps = summary["time_steps"]
    assert len(steps) == demo_series().shape[-1] and all(s["triangles"] > 0 for s in steps)
    assert summary["mesh"]["dihedral_angles_degrees"]["relaxed"]["p1"] > 15
    # The smaller blob (x < 0 at t = 0) keeps one label from start to merge.
    saved = np.load(tmp_path / "demo_time_iso.npz")
    vertices, labels = saved["vertices"], saved["labels"]
    first = np.isclose(vertices[:, 3], 0) & (vertices[:, 0] < 1.0)
    assert len(np.unique(labels[first])) == 1


def test_a_level_cutting_too_many_cells_is_refused_before_the_surface(tmp_path, capsys):
    """A 3.2 MB noise series at its median needed more than 3.5 GB; the cut cells are
    counted first and checked against the memory limit: one line, exit 2, nothing
    written, under 50 MB (the surface of this one would take about 0.4 GB). Under the
    limit the run is unchanged."""
    import tracemalloc

    from volseg.spacetime import BYTES_PER_CUT_CELL

    noise = np.random.default_rng(0).random((12, 12, 12, 6)).astype(np.float32)
    np.save(tmp_path / "noise.npy", noise)
    tracemalloc.start()
    code = main(["isosurface", str(tmp_path / "noise.npy"), "--level", "0.5", "-o",
                 str(tmp_path / "out"), "-q", "--memory-limit", "100MB"])
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1, err
    assert "noise.npy: the level 0.5 cuts" in err and "over the memory limit of 0.1 GB" in err
    assert peak < 50e6 and not list((tmp_path / "out").iterdir())
    with pytest.raises(ValueError, match="grid cells of the series"):
        segment_series(noise, 0.5, memory_limit=BYTES_PER_CUT_CELL * 100)
    series = demo_series(12, 4)
    loose = segment_series(series, 0.5, relax=0, n_regions=3)
    bound = segment_series(series, 0.5, relax=0, n_regions=3, memory_limit=2**34)
    np.testing.assert_array_equal(loose.segmentation.labels, bound.segmentation.labels)
