"""Closed and periodic test hypersurfaces: polygons, n-spheres, cylinders."""

from __future__ import annotations

import itertools

import numpy as np
from numpy.typing import NDArray

from .._kuhn import axis_orders
from .kuhn import kuhn_simplices

__all__ = ["polygon", "sphere", "cylinder", "subdivide"]


def polygon(n_sides: int, radius: float = 1.0):
    """Regular counter-clockwise polygon in R^2 (a 1-manifold, outward normals)."""
    t = 2 * np.pi * np.arange(n_sides) / n_sides
    vertices = radius * np.c_[np.cos(t), np.sin(t)]
    edges = np.c_[np.arange(n_sides), (np.arange(n_sides) + 1) % n_sides]
    return vertices, edges.astype(np.intp)


def _freudenthal_children(n):
    """Children of the edge-midpoint subdivision of an n-simplex.

    Returns (C, n+1, 2) pairs of parent-local vertex indices: each child vertex is
    the midpoint of the two parent vertices (equal indices: the parent vertex).
    """
    children = []
    for corner in itertools.product((0, 1), repeat=n):
        for perm in axis_orders(n):
            point = np.array(corner)
            path = [point.copy()]
            for axis in perm:
                point = point.copy()
                point[axis] += 1
                path.append(point)
            # Keep the Kuhn simplices inside {2 >= x_1 >= ... >= x_n >= 0}.
            if all((p[:-1] >= p[1:]).all() for p in path):
                children.append(path)
    out = []
    for path in children:
        child = []
        for x in path:
            lam2 = np.r_[2 - x[0], x[:-1] - x[1:], x[-1]]  # 2 * barycentric coordinates
            nz = np.flatnonzero(lam2)
            child.append((nz[0], nz[-1]))
        out.append(child)
    out = np.array(out, dtype=np.intp)
    # Keep each child's orientation equal to its parent's (sign of det in x-space).
    sign = []
    for path in children:
        e = np.array(path[1:]) - np.array(path[0])
        sign.append(np.sign(np.linalg.det(e.astype(float))) if n else 1)
    flip = np.array(sign) < 0
    out[flip, 0], out[flip, 1] = out[flip, 1].copy(), out[flip, 0].copy()
    return out


def subdivide(vertices: NDArray, simplices: NDArray):
    """One edge-midpoint (Freudenthal) subdivision: each n-simplex into 2^n, orientation kept."""
    vertices = np.asarray(vertices, dtype=np.float64)
    simplices = np.asarray(simplices, dtype=np.intp)
    n = simplices.shape[1] - 1
    pairs = _freudenthal_children(n)  # (C, n+1, 2)
    a = simplices[:, pairs[..., 0]]  # (S, C, n+1)
    b = simplices[:, pairs[..., 1]]
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    key = lo.astype(np.int64) * len(vertices) + hi
    unique, inverse = np.unique(key.ravel(), return_inverse=True)
    new_vertices = 0.5 * (vertices[unique // len(vertices)] + vertices[unique % len(vertices)])
    return new_vertices, inverse.reshape(-1, n + 1).astype(np.intp)


def sphere(dim: int = 2, radius: float = 1.0, subdivisions: int = 2):
    """Round n-sphere in R^(n+1) with outward normals: the cross-polytope, subdivided, projected.

    Parameters
    ----------
    dim : int
        n, the sphere's dimension (2: the octahedron refined; 3: the 16-cell boundary).
    radius : float
    subdivisions : int
        Edge-midpoint subdivisions; each multiplies the simplex count by 2^n.

    Returns
    -------
    vertices : (V, n+1) ndarray of float
    simplices : (2^(n+1) * 2^(n*subdivisions), n+1) ndarray of intp
    """
    d = dim + 1
    vertices = np.concatenate([np.eye(d), -np.eye(d)])
    simplices = []
    for signs in itertools.product((0, 1), repeat=d):
        simplex = [axis + d * s for axis, s in enumerate(signs)]
        # Outward: det[nu; edges] > 0 with nu the outward direction (the centroid).
        pts = vertices[simplex]
        e = pts[1:] - pts[0]
        if np.linalg.det(np.vstack([pts.mean(axis=0), e])) < 0:
            simplex[0], simplex[1] = simplex[1], simplex[0]
        simplices.append(simplex)
    simplices = np.array(simplices, dtype=np.intp)
    for _ in range(subdivisions):
        vertices, simplices = subdivide(vertices, simplices)
        vertices /= np.linalg.norm(vertices, axis=1, keepdims=True)
    return radius * vertices, simplices


def cylinder(dim: int = 2, radius: float = 1.0, n_around: int = 64, n_along: int = 9,
             length: float = 2.0):
    """S^1(r) x [-L/2, L/2]^(n-1) in R^(n+1), outward normals, Kuhn-tessellated.

    The circle is the first two coordinates; the n-1 straight axes follow.
    """
    shape = (n_around,) + (n_along,) * (dim - 1)
    simplices = kuhn_simplices(shape, periodic=(0,), upward=False)
    grid = np.stack(np.meshgrid(*[np.arange(s) for s in shape], indexing="ij"), -1).reshape(-1, dim)
    theta = 2 * np.pi * grid[:, 0] / n_around
    straight = -length / 2 + length * grid[:, 1:] / max(n_along - 1, 1)
    vertices = np.c_[radius * np.cos(theta), radius * np.sin(theta), straight]
    pts = vertices[simplices[0]]
    e = pts[1:] - pts[0]
    outward = np.r_[pts.mean(axis=0)[:2], np.zeros(dim - 1)]
    if np.linalg.det(np.vstack([outward, e])) < 0:
        simplices[:, [0, 1]] = simplices[:, [1, 0]]
    return vertices, simplices
