"""Shared pieces of the mesh operators: their input and the checks on it."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from .. import mesh as _mesh


class MeshParts(NamedTuple):
    """What every mesh operator receives: a checked mesh and its shared pieces."""

    vertices: NDArray[np.float64]       # (V, n+1)
    simplices: NDArray[np.intp]         # (S, n+1)
    faces: _mesh.Faces
    raw_normals: NDArray[np.float64]    # (S, n+1), |raw| = n! |sigma|
    volumes: NDArray[np.float64]        # (S,) n-volumes


def edge_gram(edges: NDArray[np.float64]) -> NDArray[np.float64]:
    """(S, k, k) Gram matrices E E^T of stacked edge vectors."""
    return edges @ edges.transpose(0, 2, 1)


def check_nondegenerate(edges, simplices, volumes) -> None:
    """Refuse simplices whose n-volume is zero relative to their edge lengths."""
    flat = _mesh.flat_by_edges(edges, volumes)
    if flat.any():
        first = int(np.flatnonzero(flat)[0])
        raise ValueError(
            f"{int(flat.sum())} simplices have zero volume (first: simplex {first} = "
            f"{simplices[first].tolist()}); curvature is undefined on degenerate simplices"
        )


def require_manifold(simplices, faces: _mesh.Faces, n_vertices: int) -> None:
    """Refuse pinched vertices (a star in two or more pieces)."""
    pinched = _mesh.pinched_vertices(simplices, n_vertices, faces)
    if len(pinched):
        raise ValueError(
            f"{len(pinched)} vertices are pinched (their star is in several pieces, e.g. two "
            f"surfaces touching at a point; first: vertex {int(pinched[0])}): the mesh is not "
            "a manifold there and curvature is undefined"
        )


def require_consistent(faces: _mesh.Faces) -> None:
    if not faces.consistent.all():
        bad = int(np.flatnonzero(~faces.consistent)[0])
        pair = faces.simplices[bad].tolist()
        raise ValueError(
            f"the mesh is not consistently oriented (simplices {pair[0]} and {pair[1]} induce "
            f"the same orientation on face {faces.vertices[bad].tolist()}); "
            "re-orient it with volseg.mesh.orient"
        )
