"""
Segment a mesh
==============

The Morse stage and the curvature work on any simplicial mesh, not only on a
volume's graph: here a triangle mesh (a 2-manifold in R^3) of three merged blobs,
made by marching cubes, is cut into its bumps by its mean curvature.
"""

import numpy as np
from skimage.measure import marching_cubes

from volseg import segment_mesh
from volseg.datasets import demo_volume

vertices, triangles, _, _ = marching_cubes(demo_volume(48), level=0.35)
result = segment_mesh(vertices, triangles, n_regions=6)
sizes = np.bincount(result.labels)[1:]
print(f"{len(vertices)} vertices, {len(triangles)} triangles: {result.n_regions} regions "
      f"of {sorted(sizes.tolist(), reverse=True)} vertices")

# %%
# The regions as a PLY-free VTK file for ParaView (meshio, one of volseg's
# dependencies), the labels and the curvature as point data.
import meshio  # noqa: E402

meshio.write("blobs_regions.vtu", meshio.Mesh(
    vertices, [("triangle", triangles)],
    point_data={"labels": result.labels, "curvature": result.curvature}))
