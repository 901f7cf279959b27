"""The files of one space-time segmentation (`volseg isosurface`), written as one set.

- ``<stem>_iso.npz``: vertices (V, 4), tetrahedra (S, 4), curvature and labels per
  vertex, boundary faces, each vertex's grid edge, and the level, spacing and shape;
- ``<stem>_iso.pvd`` with ``<stem>_iso_tNNNN.vtu``: a ParaView time series, the
  isosurface of each time step (exact slices of the space-time mesh) in the input's
  world coordinates, with point normals, coloured by the space-time curvature and
  labels, at the input's time values (written with meshio);
- ``<stem>_iso_summary.json``: strict JSON, the summary shared with volumes plus
  the mesh, its quality and the regions present at each step;
- ``<stem>_iso_preview.png``: three time steps side by side, regions coloured, so a
  feature can be followed through time.

Written through `volseg.io.OutputSet`: locked, checked up front, all or nothing.
"""

from __future__ import annotations

from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np

from .. import _json
from ._summary import input_summary, result_summary

__all__ = ["series_output_names", "series_summary", "write_series_segmentation",
           "world_points"]


def series_output_names(stem: str, steps: int) -> dict:
    """Kind -> file name of the outputs of a series of `steps` time steps."""
    names = {"mesh": f"{stem}_iso.npz", "pvd": f"{stem}_iso.pvd",
             "summary": f"{stem}_iso_summary.json", "preview": f"{stem}_iso_preview.png"}
    for step in range(steps):
        names[f"t{step:04d}"] = f"{stem}_iso_t{step:04d}.vtu"
    return names


def series_summary(result, slices, *, name, source=None, checksum=None, files=()) -> dict:
    """The summary of a `SpaceTimeSegmentation` (strict-JSON ready)."""
    seg = result.segmentation
    steps = []
    for piece in slices:
        present = np.unique(seg.labels[piece.vertex]) if len(piece.vertex) else np.zeros(0, int)
        steps.append({"step": piece.step, "triangles": int(len(piece.triangles)),
                      "regions": [int(r) for r in present if r > 0]})
    return {
        **input_summary(name, source, checksum, files),
        "kind": "space-time isosurface (x, y, z, t) as a tetrahedral 3-manifold in R^4",
        "shape": list(result.shape),
        "spacing": list(result.spacing[:3]),
        "time_scale": result.spacing[3],
        "level": result.level,
        "relax_rounds": result.relax,
        "mesh": {"vertices": int(len(result.surface.vertices)),
                 "tetrahedra": int(len(result.surface.simplices)),
                 "boundary_faces": int(len(result.surface.boundary_faces)),
                 "dihedral_angles_degrees": result.quality},
        "boundary": seg.mask.rule,
        "smooth_rounds": int(seg.smooth_rounds),
        "labels": "per vertex: regions 1..k, 0 for vertices left out",
        **result_summary(seg),
        "time_steps": steps,
        "timings_s": {k: round(v, 4) for k, v in result.timings.items()},
    }


def _write_pvd(path, vtu_names, times):
    rows = "\n".join(f'    <DataSet timestep="{t!r}" group="" part="0" file={quoteattr(n)}/>'
                     for t, n in zip(times, vtu_names, strict=True))
    Path(path).write_text('<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1">\n'
                          f"  <Collection>\n{rows}\n  </Collection>\n</VTKFile>\n")


def world_points(result, frame) -> tuple:
    """(V, 3) world positions and (V, 3) unit normals of the space-time mesh's vertices
    in `frame` (the input's: origin, rotation, voxel sizes). The mesh is built in
    voxel units times the spacing; its 4-D vertex normals' spatial parts are each step's
    surface normals (toward lower values), carried to the world by the inverse
    transpose. A vertex where the surface is flat in space (a feature appearing) gets
    a zero normal."""
    from ..mesh import per_vertex_normals

    spacing = np.asarray(result.spacing[:3], dtype=np.float64)
    linear = frame.affine[:3, :3] / spacing               # spaced mesh units -> world
    vertices = result.surface.vertices
    points = vertices[:, :3] @ linear.T + frame.affine[:3, 3]
    normals = per_vertex_normals(vertices, result.surface.simplices)[:, :3]
    normals = normals @ np.linalg.inv(linear)              # (inverse transpose) applied
    with np.errstate(invalid="ignore", divide="ignore"):
        normals = normals / np.linalg.norm(normals, axis=1, keepdims=True)
    return points, np.nan_to_num(normals, nan=0.0)


def _write_vtu(path, result, piece, points, normals, unit=None):
    """One step's slice as a ``.vtu``: the arrays named as in the ``.vti`` / ``.vts``
    (``labels``, ``curvature``), the world's `unit` as the field data ``unit``."""
    import meshio

    from ..io.vtk_image import field_data

    seg = result.segmentation
    triangles = _wound_with(piece.triangles, points[piece.vertex], normals[piece.vertex])
    cells = [("triangle", triangles)] if len(triangles) else []
    mesh = meshio.Mesh(points[piece.vertex], cells, point_data={
        "curvature": seg.curvature[piece.vertex].astype(np.float32),
        "labels": seg.labels[piece.vertex].astype(np.int32),
        "vertex": piece.vertex.astype(np.int64),
        "Normals": normals[piece.vertex].astype(np.float32)})
    meshio.write(path, mesh, file_format="vtu")
    # meshio names no attribute: mark the normals (ParaView shades with them) and the
    # labels as the active scalars. Appended-data offsets count from the data section,
    # so the longer header moves nothing.
    # The unit's field data goes before the piece (no appended data moves either).
    text = Path(path).read_bytes().replace(
        b"<PointData>", b'<PointData Normals="Normals" Scalars="labels">', 1)
    if unit:
        text = text.replace(b"<Piece ", field_data(unit).encode() + b"<Piece ", 1)
    Path(path).write_bytes(text)


def _wound_with(triangles, points, normals):
    """`triangles` each wound so that its right-hand normal agrees with its vertices'
    normals (a slice's triangles come in either order; ParaView shades a triangle
    wound against its point normals dark: a checkerboard)."""
    triangles = np.asarray(triangles)
    if not len(triangles):
        return triangles
    corners = points[triangles]
    face = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    against = np.einsum("ij,ij->i", face, normals[triangles].sum(axis=1)) < 0
    out = triangles.copy()
    out[against] = out[against][:, [0, 2, 1]]
    return out


def _preview_steps(slices) -> list:
    """First, middle and last non-empty time steps."""
    filled = [s for s in slices if len(s.triangles)]
    if len(filled) <= 3:
        return filled
    return [filled[0], filled[len(filled) // 2], filled[-1]]


def write_series_preview(path, result, slices, *, title=""):
    """Three time steps side by side, each triangle coloured by its region."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    from .preview import TAB20

    chosen = _preview_steps(slices)
    seg = result.segmentation
    points = result.surface.vertices[:, :3]
    lo, hi = points.min(axis=0), points.max(axis=0)
    light = np.array([0.4, 0.3, 0.85]) / np.linalg.norm([0.4, 0.3, 0.85])
    fig = plt.figure(figsize=(4 * max(len(chosen), 1), 4.4), dpi=100)
    for column, piece in enumerate(chosen, 1):
        ax = fig.add_subplot(1, len(chosen), column, projection="3d")
        triangles = points[piece.vertex][piece.triangles]
        labels = seg.labels[piece.vertex][piece.triangles[:, 0]]
        normal = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
        normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-300)
        shade = 0.45 + 0.55 * np.abs(normal @ light)
        colours = TAB20[(labels - 1) % len(TAB20)] / 255.0 * shade[:, None]
        colours[labels == 0] = 0.6 * shade[labels == 0, None]
        ax.add_collection3d(Poly3DCollection(triangles, facecolors=colours, linewidths=0))
        ax.set(xlim=(lo[0], hi[0]), ylim=(lo[1], hi[1]), zlim=(lo[2], hi[2]),
               xlabel="x", ylabel="y", zlabel="z")
        ax.set_box_aspect(np.maximum(hi - lo, 1e-9))
        ax.set_title(f"t = {piece.step}: regions {sorted(set(labels.tolist()) - {0})[:8]}"
                     + ("..." if len(set(labels.tolist()) - {0}) > 8 else ""), fontsize=9)
        ax.tick_params(labelsize=7)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return Path(path)


def write_series_segmentation(outputs, result, slices, info: dict, *, title: str,
                              frame=None, time_step: float = 1.0,
                              time_offset: float = 0.0) -> dict:
    """Write mesh, ParaView series, summary and preview of `result` as one set: the
    series' meshes in `frame`'s world coordinates (default: the spacing alone), their
    time values `time_step` apart from `time_offset` (a NIfTI's toffset)."""
    from ..io import Frame

    info = {**info, "outputs": {kind: str(path) for kind, path in outputs.targets.items()}}
    seg = result.segmentation
    surface = result.surface
    frame = frame or Frame.from_spacing(result.spacing[:3])
    points, normals = world_points(result, frame)

    def write(paths):
        np.savez_compressed(paths["mesh"], vertices=surface.vertices, tetrahedra=surface.simplices,
                            curvature=seg.curvature, labels=seg.labels,
                            boundary_faces=surface.boundary_faces, grid_edges=surface.edges,
                            level=result.level, spacing=np.asarray(result.spacing),
                            shape=np.asarray(result.shape))
        names = []
        for piece in slices:
            target = paths[f"t{piece.step:04d}"]
            _write_vtu(target, result, piece, points, normals, frame.unit)
            names.append(Path(outputs.targets[f"t{piece.step:04d}"]).name)
        _write_pvd(paths["pvd"], names,
                   [time_offset + float(s.step) * time_step for s in slices])
        write_series_preview(paths["preview"], result, slices, title=title)
        Path(paths["summary"]).write_text(_json.dumps(info, indent=2))

    outputs.commit(write)
    return info
