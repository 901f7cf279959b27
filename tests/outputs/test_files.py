"""volseg.outputs: the names of an output set, the summary and title of a result, and
the one writer (in-memory labels written, stored ones kept)."""

import json

import nibabel
import numpy as np
import pytest

from volseg import segment_volume
from volseg.io import Frame, write_zarr
from volseg.outputs import (
    BLOCKWISE_NIFTI_VOXELS,
    PARAVIEW_VOXELS,
    all_output_names,
    output_names,
    result_title,
    summary,
    write_result_files,
)


def test_output_names_of_each_path():
    assert output_names("s") == {"labels": "s_labels.nii.gz", "curvature": "s_curvature.nii.gz",
                                 "summary": "s_summary.json", "preview": "s_preview.png",
                                 "paraview": "s_volumes.vti", "ngff": "s_segmentation.ome.zarr"}
    assert "paraview" not in output_names("s", voxels=PARAVIEW_VOXELS + 1)
    assert "paraview" not in output_names("s", paraview=False)
    assert "paraview" in output_names("s", voxels=PARAVIEW_VOXELS + 1, paraview=True)
    assert output_names("s", axis_aligned=False)["paraview"] == "s_volumes.vts"
    assert {"s_volumes.vti", "s_volumes.vts"} <= all_output_names("s")
    big = output_names("s", blockwise=True, voxels=BLOCKWISE_NIFTI_VOXELS + 1)
    assert big["labels"] == "s_labels.zarr" and big["curvature"] == "s_curvature.zarr"
    assert "labels_nifti" not in big
    small = output_names("s", persistence_plot=True, blockwise=True, voxels=8)
    assert small["labels_nifti"] == "s_labels.nii.gz"
    assert small["persistence"] == "s_persistence.png"


@pytest.fixture(scope="module")
def result():
    rng = np.random.default_rng(2)
    volume = rng.random((12, 10, 8))
    volume[:, :, :4] = 0.0                    # a plateau of half the voxels and one more
    volume[0, 0, 4] = 0.0
    return volume, segment_volume(volume, n_regions=3, mask="auto", smooth_sigma=0.5,
                                  spacing=(1.0, 2.0, 0.5))


def test_title_and_summary_name_what_was_done(result):
    volume, seg = result
    assert result_title("v", seg) == ("v: 3 regions, weighted curvature, smoothed sigma 0.5, "
                                      "mask nonzero")
    assert result_title("v", seg, blockwise=True).endswith(" (blockwise)")
    info = summary(seg, name="v", noise=None)
    assert info["n_regions"] == 3 and len(info["regions"]) == 3
    assert sum(r["size"] for r in info["regions"]) == info["mask"]["voxels"] == seg.mask.voxels
    assert info["smooth_sigma_voxels"] == 0.5 and info["padding"] == "linear"
    assert info["spacing"] == [1.0, 2.0, 0.5]
    assert info["affine"] == np.diag([1.0, 2.0, 0.5, 1.0]).tolist()
    assert set(info["timings_s"]) == {"curvature", "morse", "cut", "labels"}
    json.dumps(info)                          # strict-JSON ready


def test_the_writer_writes_nifti_and_keeps_what_storage_wrote(result, tmp_path):
    volume, seg = result
    frame = Frame.from_spacing(seg.spacing)
    paths = {kind: tmp_path / name for kind, name in output_names(
        "v", blockwise=True, voxels=volume.size).items()}
    write_zarr(paths["curvature"], seg.curvature, frame=frame)    # as the storage would
    stored = sorted(p.name for p in paths["curvature"].rglob("*"))
    write_result_files(paths, seg, volume, {"n_regions": 3}, frame=frame, title="t")
    labels = nibabel.load(paths["labels_nifti"])
    assert labels.get_data_dtype() == np.uint8
    assert np.array_equal(np.asarray(labels.dataobj), seg.labels)
    assert np.allclose(labels.affine, frame.affine)
    curvature = nibabel.load(paths["curvature_nifti"])
    assert np.array_equal(np.asarray(curvature.dataobj), seg.curvature.astype(np.float32))
    assert sorted(p.name for p in paths["curvature"].rglob("*")) == stored     # kept
    assert paths["labels"].exists()           # the Zarr labels the storage had not written
    assert json.loads(paths["summary"].read_text()) == {"n_regions": 3}
    assert paths["preview"].stat().st_size > 1000
