"""The outputs opened with the programs' own libraries (issue 28): nibabel and
SimpleITK for the NIfTI label maps, VTK's readers (ParaView's) for the ParaView files.
The input is rotated, translated and in micrometres."""

import json

import nibabel
import numpy as np
import pytest

from volseg.cli import main

#: voxel (i, j, k) -> world, in micrometres: rotated about z, flipped in z, translated.
ROTATED_UM = np.array([[0.0, -0.5, 0.0, 12.0], [0.4, 0.0, 0.0, -3.5], [0.0, 0.0, -0.8, 7.25],
                       [0.0, 0.0, 0.0, 1.0]])


def _blobs(shape=(20, 18, 16)):
    x, y, z = np.meshgrid(*[np.linspace(-1, 1, s) for s in shape], indexing="ij")
    field = (200 * np.exp(-4 * ((x - 0.35) ** 2 + y**2 + z**2))
             + 140 * np.exp(-5 * ((x + 0.4) ** 2 + (y - 0.3) ** 2 + z**2)))
    return np.round(field).astype(np.uint8)


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    folder = tmp_path_factory.mktemp("clients")
    image = nibabel.Nifti1Image(_blobs(), ROTATED_UM)
    image.header.set_sform(ROTATED_UM, 2)
    image.header.set_qform(ROTATED_UM, 1)
    image.header.set_xyzt_units("micron", "sec")
    nibabel.save(image, folder / "cell.nii.gz")
    assert main(["segment", str(folder / "cell.nii.gz"), "-o", str(folder / "out"), "-q",
                 "--regions", "3"]) == 0
    return folder / "out"


def test_nifti_label_map_headers_in_nibabel(run):
    labels = nibabel.load(run / "cell_labels.nii.gz")
    header = labels.header
    assert header.get_intent()[0] == "label"
    assert header.get_xyzt_units()[0] == "micron"             # not a hard-coded mm
    assert (float(header["cal_min"]), float(header["cal_max"])) == (0.0, 3.0)
    assert b"labels 1..3" in bytes(header["descrip"])
    np.testing.assert_allclose(labels.affine, ROTATED_UM)
    assert set(np.unique(np.asarray(labels.dataobj))) - {0} == {1, 2, 3}     # 0: masked
    curvature = nibabel.load(run / "cell_curvature.nii.gz")
    values = np.asarray(curvature.dataobj)
    assert curvature.header.get_intent()[0] == "none"
    assert curvature.header.get_xyzt_units()[0] == "micron"
    assert float(curvature.header["cal_max"]) == pytest.approx(np.nanmax(values))
    assert b"mean curvature" in bytes(curvature.header["descrip"])


def test_nifti_outputs_in_simpleitk(run):
    sitk = pytest.importorskip("SimpleITK")
    labels = sitk.ReadImage(str(run / "cell_labels.nii.gz"))
    # ITK's world is LPS (the RAS affine with x and y negated) in millimetres: the
    # micrometre header is converted, where a hard-coded 'mm' made it 1000x too large.
    lps = np.diag([-1.0, -1.0, 1.0]) @ ROTATED_UM[:3] / 1000
    np.testing.assert_allclose(labels.GetOrigin(), lps[:, 3], rtol=1e-6)
    np.testing.assert_allclose(labels.GetSpacing(), np.linalg.norm(lps[:, :3], axis=0),
                               rtol=1e-6)
    direction = np.array(labels.GetDirection()).reshape(3, 3)
    np.testing.assert_allclose(direction * labels.GetSpacing(), lps[:, :3], atol=1e-9)
    array = sitk.GetArrayFromImage(labels)                    # (z, y, x)
    np.testing.assert_array_equal(array.transpose(2, 1, 0),
                                  np.asarray(nibabel.load(run / "cell_labels.nii.gz").dataobj))


def _vtk_file(path):
    """(dataset, name -> [x, y, z] array) of a ParaView file, read by VTK's own XML
    reader (ParaView's): an image (.vti) or a structured grid (.vts)."""
    vtk = pytest.importorskip("vtk")
    from vtk.util.numpy_support import vtk_to_numpy

    reader = (vtk.vtkXMLStructuredGridReader() if path.suffix == ".vts"
              else vtk.vtkXMLImageDataReader())
    reader.SetFileName(str(path))
    reader.Update()
    data = reader.GetOutput()
    extent = data.GetExtent()
    shape = tuple(extent[2 * a + 1] - extent[2 * a] + 1 for a in range(3))
    arrays = {}
    for i in range(data.GetPointData().GetNumberOfArrays()):
        array = data.GetPointData().GetArray(i)
        arrays[array.GetName()] = vtk_to_numpy(array).reshape(shape[::-1]).transpose(2, 1, 0)
    return data, arrays


def _contour_bounds(data, name, level):
    """(xmin, xmax, ymin, ymax, zmin, zmax) of VTK's `vtkContourFilter` isosurface of
    array `name` at `level`: the filter ParaView's Contour runs."""
    import vtk

    data.GetPointData().SetActiveScalars(name)
    contour = vtk.vtkContourFilter()
    contour.SetInputData(data)
    contour.SetValue(0, level)
    contour.Update()
    return np.array(contour.GetOutput().GetBounds())


def _world_isosurface_bounds(values, affine, level):
    """The same isosurface computed in voxel indices (an unrotated image), its points
    taken to the world by the NIfTI's affine (linear: the isosurface's points map
    exactly): the bounds a correctly placed file must give."""
    import vtk
    from vtk.util.numpy_support import numpy_to_vtk, vtk_to_numpy

    image = vtk.vtkImageData()
    image.SetDimensions(*values.shape)
    image.GetPointData().SetScalars(numpy_to_vtk(values.transpose(2, 1, 0).ravel().astype(
        np.float64)))
    contour = vtk.vtkContourFilter()
    contour.SetInputData(image)
    contour.SetValue(0, level)
    contour.Update()
    points = vtk_to_numpy(contour.GetOutput().GetPoints().GetData())
    world = points @ affine[:3, :3].T + affine[:3, 3]
    return np.ravel(np.column_stack([world.min(0), world.max(0)]))


def test_paraview_file_of_an_oblique_scan_places_contour_where_the_scan_is(run):
    """An oblique, flipped, micrometre scan's ParaView file is a structured grid with
    every voxel's world position (issue 58): VTK's Contour (which ignores an image's
    Direction) draws the isosurface where the NIfTI puts it; the arrays are the NIfTI
    outputs'; the unit is the field data's."""
    assert not (run / "cell_volumes.vti").exists()
    grid, arrays = _vtk_file(run / "cell_volumes.vts")
    assert grid.GetClassName() == "vtkStructuredGrid"
    assert sorted(arrays) == ["curvature", "labels", "values"]
    np.testing.assert_array_equal(arrays["values"], _blobs())
    np.testing.assert_array_equal(arrays["labels"],
                                  np.asarray(nibabel.load(run / "cell_labels.nii.gz").dataobj))
    np.testing.assert_array_equal(
        arrays["curvature"], np.asarray(nibabel.load(run / "cell_curvature.nii.gz").dataobj))
    for index in [(0, 0, 0), (19, 0, 0), (3, 17, 11), (19, 17, 15)]:
        flat = index[0] + 20 * (index[1] + 18 * index[2])         # x fastest
        np.testing.assert_allclose(grid.GetPoint(flat), (ROTATED_UM @ [*index, 1])[:3],
                                   atol=1e-5)
    affine = nibabel.load(run / "cell_labels.nii.gz").affine
    for name, level in (("values", 100.0), ("labels", 1.5)):
        np.testing.assert_allclose(_contour_bounds(grid, name, level),
                                   _world_isosurface_bounds(arrays[name], affine, level),
                                   atol=1e-3)
    assert grid.GetFieldData().GetAbstractArray("unit").GetValue(0) == "micrometer"


def test_paraview_image_of_an_axis_aligned_scan(tmp_path):
    """An axis-aligned scan's ParaView file stays an image (.vti: 9 bytes per voxel,
    not 21-33), placed by origin and spacing, Contour included."""
    affine = np.array([[0.5, 0, 0, 3.0], [0, 0.4, 0, -2.0], [0, 0, 0.8, 1.0], [0, 0, 0, 1]])
    image = nibabel.Nifti1Image(_blobs(), affine)
    image.header.set_xyzt_units("mm")
    nibabel.save(image, tmp_path / "cell.nii.gz")
    assert main(["segment", str(tmp_path / "cell.nii.gz"), "-o", str(tmp_path / "out"), "-q",
                 "--regions", "3"]) == 0
    assert not (tmp_path / "out" / "cell_volumes.vts").exists()
    data, arrays = _vtk_file(tmp_path / "out" / "cell_volumes.vti")
    assert data.GetClassName() == "vtkImageData"
    np.testing.assert_allclose(_contour_bounds(data, "values", 100.0),
                               _world_isosurface_bounds(arrays["values"], affine, 100.0),
                               atol=1e-3)
    assert data.GetFieldData().GetAbstractArray("unit").GetValue(0) == "millimeter"


def test_blockwise_writes_the_same_paraview_file(run, tmp_path):
    assert main(["segment", str(run.parent / "cell.nii.gz"), "-o", str(tmp_path), "-q",
                 "--regions", "3", "--chunks", "7"]) == 0
    blockwise_grid, blockwise = _vtk_file(tmp_path / "cell_volumes.vts")
    memory_grid, memory = _vtk_file(run / "cell_volumes.vts")
    for name in memory:
        np.testing.assert_array_equal(blockwise[name], memory[name])
    from vtk.util.numpy_support import vtk_to_numpy

    np.testing.assert_array_equal(vtk_to_numpy(blockwise_grid.GetPoints().GetData()),
                                  vtk_to_numpy(memory_grid.GetPoints().GetData()))


def _ngff_nodes(path):
    from ome_zarr.io import parse_url
    from ome_zarr.reader import Reader

    return {node.metadata.get("name") or "": node for node in Reader(parse_url(str(path)))()}


def test_ome_zarr_opens_as_an_image_with_its_labels_in_ome_zarr_py(run):
    """ome-zarr-py's reader (napari-ome-zarr's): the curvature image and its labels
    image, axes z, y, x, the input's voxel sizes, origin and micrometres (NGFF has no
    rotation: the frame is written axis aligned)."""
    nodes = _ngff_nodes(run / "cell_segmentation.ome.zarr")
    image, labels = nodes["curvature"], nodes["regions"]
    assert [type(s).__name__ for s in labels.specs] == ["Label", "Multiscales"]
    for node in (image, labels):
        assert [a["name"] for a in node.metadata["axes"]] == ["z", "y", "x"]
        assert {a["unit"] for a in node.metadata["axes"]} == {"micrometer"}
        scale, translation = node.metadata["coordinateTransformations"][0]
        np.testing.assert_allclose(scale["scale"], [0.8, 0.5, 0.4])
        np.testing.assert_allclose(translation["translation"], [7.25, -3.5, 12.0])
    nifti = np.asarray(nibabel.load(run / "cell_labels.nii.gz").dataobj)
    np.testing.assert_array_equal(np.asarray(labels.data[0]), nifti.transpose(2, 1, 0))
    curvature = np.asarray(nibabel.load(run / "cell_curvature.nii.gz").dataobj)
    np.testing.assert_array_equal(np.asarray(image.data[0]), curvature.transpose(2, 1, 0))


def test_ngff_pyramids_sample_labels_and_average_curvature(tmp_path):
    """Labels are sampled (every second voxel, the same first centre), the curvature
    averaged over 2 x 2 x 2 (its centre half a voxel on): levels down to 64 voxels."""
    from volseg.io import Frame, write_ngff

    rng = np.random.default_rng(1)
    labels = rng.integers(0, 7, (150, 140, 130)).astype(np.uint8)
    curvature = rng.normal(size=labels.shape)
    write_ngff(tmp_path / "p.ome.zarr", labels, curvature,
               Frame.from_spacing((1.0, 2.0, 3.0), unit="millimeter"))
    nodes = _ngff_nodes(tmp_path / "p.ome.zarr")
    regions, image = nodes["regions"], nodes["curvature"]
    assert [d.shape for d in regions.data] == [(130, 140, 150), (65, 70, 75), (33, 35, 38)]
    zyx = labels.transpose(2, 1, 0)
    np.testing.assert_array_equal(np.asarray(regions.data[1]), zyx[::2, ::2, ::2])
    mean = curvature.transpose(2, 1, 0)[:130, :140, :150].reshape(65, 2, 70, 2, 75, 2)
    np.testing.assert_allclose(np.asarray(image.data[1]), mean.mean(axis=(1, 3, 5)),
                               atol=1e-6)
    for node, shift in ((regions, 0.0), (image, 0.5)):
        scale, translation = node.metadata["coordinateTransformations"][1]
        np.testing.assert_allclose(scale["scale"], [6.0, 4.0, 2.0])
        np.testing.assert_allclose(translation["translation"], np.array([3.0, 2.0, 1.0]) * shift)


def test_ngff_written_in_blocks_of_chunks_the_same_from_any_blocks(tmp_path):
    """A Dask result in odd blocks writes the image a numpy one does: the same files,
    metadata and values (64^3 chunks, means rounded once), each task a block of
    chunks: a task per 64^3 chunk was most of a 1024^3 run's tasks on a cluster."""
    import json

    import dask.array as da
    import zarr
    from dask.callbacks import Callback

    from volseg.io import Frame, write_ngff

    rng = np.random.default_rng(2)
    labels = rng.integers(0, 9, (300, 260, 141)).astype(np.uint8)  # odd: a trimmed slab
    curvature = rng.normal(size=labels.shape)
    frame = Frame.from_spacing((0.5, 1.0, 2.0))
    write_ngff(tmp_path / "memory.ome.zarr", labels, curvature, frame)
    write_ngff(tmp_path / "blocks.ome.zarr", da.from_array(labels, chunks=(100, 64, 70)),
               da.from_array(curvature, chunks=(100, 64, 70)), frame)
    tasks = []
    with Callback(pretask=lambda key, dask, state: tasks.append(key)):
        write_ngff(tmp_path / "aligned.ome.zarr", da.from_array(labels, chunks=(256, 256, 141)),
                   da.from_array(curvature, chunks=(256, 256, 141)), frame)
    chunks = -(-300 // 64) * -(-260 // 64) * -(-141 // 64)       # 5 x 5 x 3 at level 0
    assert len(tasks) < chunks, len(tasks)     # a task per chunk and its rechunk: 813 tasks
    paths = sorted(p.relative_to(tmp_path / "memory.ome.zarr")
                   for p in (tmp_path / "memory.ome.zarr").rglob("*") if p.is_file())
    assert paths == sorted(p.relative_to(tmp_path / "blocks.ome.zarr")
                           for p in (tmp_path / "blocks.ome.zarr").rglob("*") if p.is_file())
    for path in paths:
        one, other = (tmp_path / run / path for run in ("memory.ome.zarr", "blocks.ome.zarr"))
        if path.name == "zarr.json":
            assert json.loads(one.read_text()) == json.loads(other.read_text()), path
    for level in ("s0", "s1", "s2", "labels/regions/s0", "labels/regions/s1",
                  "labels/regions/s2"):
        one, other = (zarr.open_array(str(tmp_path / run / level), mode="r")
                      for run in ("memory.ome.zarr", "blocks.ome.zarr"))
        assert one.chunks == tuple(min(64, n) for n in one.shape)
        np.testing.assert_array_equal(one[...], other[...])


def test_isosurface_series_in_world_space_with_real_time_and_normals(tmp_path):
    """A 4-D NIfTI, rotated, translated, 2.5 s per step from 5 s (toffset): the .pvd's
    time values are 5, 7.5, 10, ..., every .vtu's triangles are wound with their point
    normals, every .vtu (read with VTK's XML reader, ParaView's) sits in the
    input's world coordinates (its points are the affine of the mesh's voxel
    positions) and carries unit point normals as its Normals attribute."""
    import xml.etree.ElementTree as ElementTree

    vtk = pytest.importorskip("vtk")
    from vtk.util.numpy_support import vtk_to_numpy

    from volseg.datasets import demo_series

    series = demo_series(14, 4)
    affine = np.eye(4)
    affine[:3] = ROTATED_UM[:3]
    image = nibabel.Nifti1Image(series, affine)
    image.header.set_sform(affine, 2)
    image.header.set_xyzt_units("micron", "sec")
    image.header["pixdim"][4] = 2.5
    image.header["toffset"] = 5.0                 # the first step at 5 s
    nibabel.save(image, tmp_path / "run.nii.gz")
    assert main(["isosurface", str(tmp_path / "run.nii.gz"), "--level", "0.5", "-o",
                 str(tmp_path / "o"), "-q", "--regions", "2", "--relax", "0"]) == 0
    collection = ElementTree.parse(tmp_path / "o" / "run_iso.pvd").getroot()
    steps = collection.findall("./Collection/DataSet")
    assert [float(s.get("timestep")) for s in steps] == [5.0, 7.5, 10.0, 12.5]
    mesh = np.load(tmp_path / "o" / "run_iso.npz")
    spacing = mesh["spacing"][:3]
    affine = nibabel.load(tmp_path / "run.nii.gz").affine         # as stored (float32)
    for dataset in steps:
        reader = vtk.vtkXMLUnstructuredGridReader()
        reader.SetFileName(str(tmp_path / "o" / dataset.get("file")))
        reader.Update()
        grid = reader.GetOutput()
        # The unit as the .vts and .vti say it; the arrays named as theirs.
        assert grid.GetFieldData().GetAbstractArray("unit").GetValue(0) == "micrometer"
        assert grid.GetPointData().GetScalars().GetName() == "labels"
        if not grid.GetNumberOfPoints():
            continue
        points = vtk_to_numpy(grid.GetPoints().GetData())
        vertex = vtk_to_numpy(grid.GetPointData().GetArray("vertex"))
        voxel = mesh["vertices"][vertex, :3] / spacing            # voxel index positions
        np.testing.assert_allclose(points, voxel @ affine[:3, :3].T + affine[:3, 3],
                                   atol=1e-9)
        normals = vtk_to_numpy(grid.GetPointData().GetNormals())
        lengths = np.linalg.norm(normals, axis=1)
        assert np.all((np.abs(lengths - 1) < 1e-5) | (lengths == 0)) and lengths.mean() > 0.9
        # Toward lower values: along each vertex's grid edge from its higher end to its
        # lower one (edges along t have no direction in space).
        ends = mesh["grid_edges"][vertex]
        index = np.stack(np.unravel_index(ends.ravel(), series.shape), 1).reshape(-1, 2, 4)
        values = series.ravel()[ends]
        high = np.where((values[:, 0] > values[:, 1])[:, None], index[:, 0], index[:, 1])
        low = np.where((values[:, 0] > values[:, 1])[:, None], index[:, 1], index[:, 0])
        downhill = (low - high)[:, :3] @ affine[:3, :3].T
        spatial = np.linalg.norm(downhill, axis=1) > 0
        assert np.mean(np.sum(normals * downhill, axis=1)[spatial] > 0) > 0.95
        # Every triangle wound with its point normals (else ParaView shades half dark).
        cells = vtk_to_numpy(grid.GetCells().GetConnectivityArray()).reshape(-1, 3)
        corners = points[cells]
        face = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
        assert np.all(np.einsum("ij,ij->i", face, normals[cells].sum(axis=1)) >= 0)
    summary = __import__("json").loads((tmp_path / "o" / "run_iso_summary.json").read_text())
    assert (summary["time_step"], summary["time_unit"]) == (2.5, "second")
    assert summary["time_offset"] == 5.0


def test_napari_ome_zarr_opens_an_image_and_a_labels_layer(run):
    """napari-ome-zarr's reader function (no viewer): the curvature as an image layer,
    the regions as a labels layer, both with the input's voxel sizes and units.
    Its 0.10 reads only the first transform of dataset 0 (the scale), so it drops any
    NGFF 0.4/0.5 translation, ours included: the file has it (the test above)."""
    napari_ome_zarr = pytest.importorskip("napari_ome_zarr")

    path = str(run / "cell_segmentation.ome.zarr")
    layers = {kind: (data, options) for data, options, kind in
              napari_ome_zarr.napari_get_reader(path)(path)}
    assert sorted(layers) == ["image", "labels"]
    nifti = np.asarray(nibabel.load(run / "cell_labels.nii.gz").dataobj)
    data, options = layers["labels"]
    np.testing.assert_array_equal(np.asarray(data[0] if isinstance(data, list) else data),
                                  nifti.transpose(2, 1, 0))
    for _, options in layers.values():
        np.testing.assert_allclose(options["scale"], [0.8, 0.5, 0.4], rtol=1e-6)
        assert options["units"] == ("micrometer",) * 3


def _validated(path):
    """ome-zarr-models' reading of the OME-Zarr group at `path` (it raises when the
    group matches no NGFF model)."""
    import zarr
    from ome_zarr_models import open_ome_zarr

    return open_ome_zarr(zarr.open_group(str(path), mode="r"))


def test_the_ome_zarr_output_validates_as_ngff_0_5(run):
    """ome-zarr-py 0.18 leaves "version" out of the labels group, and ome-zarr-models
    then refused the whole image; every group of the output validates now."""
    from ome_zarr_models.v05.image import Image
    from ome_zarr_models.v05.image_label import ImageLabel

    store = run / "cell_segmentation.ome.zarr"
    assert isinstance(_validated(store), Image)
    assert isinstance(_validated(store / "labels" / "regions"), ImageLabel)
    assert json.loads((store / "labels" / "zarr.json").read_text())["attributes"]["ome"][
        "version"] == "0.5"
