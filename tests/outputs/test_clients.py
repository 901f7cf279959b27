"""The outputs opened with the programs' own libraries (issue 28): nibabel and
SimpleITK for the NIfTI label maps, VTK's readers (ParaView's) for the ParaView files.
The input is rotated, translated and in micrometres."""

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


def _vti(path):
    vtk = pytest.importorskip("vtk")
    from vtk.util.numpy_support import vtk_to_numpy

    reader = vtk.vtkXMLImageDataReader()
    reader.SetFileName(str(path))
    reader.Update()
    image = reader.GetOutput()
    shape = image.GetDimensions()
    arrays = {}
    for i in range(image.GetPointData().GetNumberOfArrays()):
        array = image.GetPointData().GetArray(i)
        arrays[array.GetName()] = vtk_to_numpy(array).reshape(shape[::-1]).transpose(2, 1, 0)
    return image, arrays


def test_paraview_image_opens_aligned_in_vtks_reader(run):
    """VTK's XML image reader (ParaView's) sees the input, curvature and labels, on the
    input's grid: index -> world equals the NIfTI affine (rotation included)."""
    image, arrays = _vti(run / "cell_volumes.vti")
    assert sorted(arrays) == ["curvature", "labels", "values"]
    np.testing.assert_array_equal(arrays["values"], _blobs())
    np.testing.assert_array_equal(arrays["labels"],
                                  np.asarray(nibabel.load(run / "cell_labels.nii.gz").dataobj))
    np.testing.assert_array_equal(
        arrays["curvature"], np.asarray(nibabel.load(run / "cell_curvature.nii.gz").dataobj))
    for index in [(0, 0, 0), (19, 0, 0), (3, 17, 11), (19, 17, 15)]:
        world = [0.0] * 3
        image.TransformIndexToPhysicalPoint(*index, world)
        np.testing.assert_allclose(world, (ROTATED_UM @ [*index, 1])[:3], atol=1e-12)


def test_blockwise_writes_the_same_paraview_image(run, tmp_path):
    assert main(["segment", str(run.parent / "cell.nii.gz"), "-o", str(tmp_path), "-q",
                 "--regions", "3", "--chunks", "7"]) == 0
    _, blockwise = _vti(tmp_path / "cell_volumes.vti")
    _, memory = _vti(run / "cell_volumes.vti")
    for name in memory:
        np.testing.assert_array_equal(blockwise[name], memory[name])
