"""Extrinsic distortion: signed bending angles at (n-1)-faces, weighted and unweighted sums."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .. import mesh as _mesh
from ._common import require_consistent

__all__ = ["bending_angles"]


def _bending(vertices, simplices, faces, raw_normals):
    """psi and |tau| at the interior faces of a checked, consistently oriented mesh."""
    interior = faces.interior
    face_vertices = faces.vertices[interior]
    sa, sb = faces.simplices[interior].T
    ca = faces.opposite[interior, 0]
    n = simplices.shape[1] - 1
    unit = raw_normals / np.linalg.norm(raw_normals, axis=1, keepdims=True)
    from ._mesh_kernels import bending_kernel

    psi = np.empty(len(face_vertices))
    measure = np.empty(len(face_vertices))
    bending_kernel(
        vertices, np.ascontiguousarray(face_vertices), simplices[sa, ca], unit, sa, sb, psi,
        measure,
    )
    return face_vertices, psi, measure / math.factorial(n - 1)


def weighted_distortion(parts):
    return extrinsic_distortion(parts, weighted=True)


def unweighted_distortion(parts):
    return extrinsic_distortion(parts, weighted=False)


def bending_angles(
    vertices: ArrayLike, simplices: ArrayLike
) -> tuple[NDArray[np.intp], NDArray[np.float64], NDArray[np.float64]]:
    """Signed bending angle psi = pi - Theta at every interior (n-1)-face.

    Parameters
    ----------
    vertices : (V, n+1) array_like of float
    simplices : (S, n+1) array_like of int
        Consistently oriented n-simplices.

    Returns
    -------
    face_vertices : (F, n) ndarray of intp
        Sorted vertex indices of each interior face.
    psi : (F,) ndarray of float
        Radians in (-pi, pi]; positive on a ridge (the hypersurface bends away from
        its normal), negative in a valley, 0 where flat.
    face_volumes : (F,) ndarray of float
        (n-1)-volume ``|tau|`` of each face (1 for n = 1).

    Examples
    --------
    >>> import numpy as np
    >>> square = np.array([[1, -1], [1, 1], [-1, 1], [-1, -1]], float)
    >>> _, psi, _ = bending_angles(square, [[0, 1], [1, 2], [2, 3], [3, 0]])
    >>> np.round(psi, 6).tolist()  # a counter-clockwise polygon bends by +pi/2 at each corner
    [1.570796, 1.570796, 1.570796, 1.570796]
    """
    vertices, simplices = _mesh.check_mesh(vertices, simplices)
    faces = _mesh.faces(simplices, len(vertices))
    require_consistent(faces)
    raw = _mesh._cofactor_normals(_mesh._edge_vectors(vertices, simplices))
    return _bending(vertices, simplices, faces, raw)


def extrinsic_distortion(parts, *, weighted):
    """Per-vertex sum of psi (unweighted) or sum psi |tau| / (n^2 |p|) (weighted)."""
    vertices, simplices, volumes = parts.vertices, parts.simplices, parts.volumes
    n = simplices.shape[1] - 1
    face_vertices, psi, measure = _bending(vertices, simplices, parts.faces, parts.raw_normals)
    values = psi * measure if weighted else psi
    total = np.bincount(
        face_vertices.ravel(), weights=np.repeat(values, n), minlength=len(vertices)
    )
    if not weighted:
        return total
    star = _mesh.to_vertices(simplices, volumes / (n + 1), len(vertices))
    with np.errstate(invalid="ignore", divide="ignore"):
        return total / (n * n * star)
