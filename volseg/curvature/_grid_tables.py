"""The tables of one Kuhn cube the grid kernels read: corner offsets, the 6
tetrahedra and their neighbours across the low sides, the 12 interior faces."""

from __future__ import annotations

import numpy as np

from .. import _kuhn

__all__ = []


def _tables():
    """Offsets of one cube's 6 tetrahedra, the 6 neighbours across its low sides, its 12 faces.

    Points are numbered 0..10: the cube corners (4 dx + 2 dy + dz) and then the
    three points one step below the cube's lowest corner along x, y, z.
    """
    unit = np.eye(3, dtype=np.int64)
    offsets = np.array([[a, b, c] for a in (0, 1) for b in (0, 1) for c in (0, 1)]
                       + [-unit[0], -unit[1], -unit[2]], dtype=np.int64)
    index = {tuple(o): n for n, o in enumerate(offsets)}
    paths = [list(map(tuple, path)) for path in _kuhn.cube_paths(3)]
    axes = [list(order) for order in _kuhn.axis_orders(3)]
    for path, (a, b, c) in zip(_kuhn.cube_paths(3), _kuhn.axis_orders(3), strict=True):
        # The tetrahedron (c, a, b) of the cube below along c shares the face
        # {0, e_a, e_a + e_b} with this cube's tetrahedron (a, b, c).
        paths.append([tuple(-unit[c]), *map(tuple, path[:3])])
        axes.append([c, a, b])
    path_idx = np.array([[index[tuple(p)] for p in path] for path in paths], dtype=np.int64)
    faces, far, tets = [], [], []
    as_set = [set(row) for row in path_idx.tolist()]
    for ta in range(6):
        for tb in range(ta + 1, 12):
            if tb >= 6 and tb != ta + 6:
                continue
            shared = as_set[ta] & as_set[tb]
            if len(shared) == 3:
                faces.append(sorted(shared))
                far.append(next(iter(as_set[tb] - shared)))
                tets.append([ta, tb])
    assert len(faces) == 12
    return (offsets, path_idx, np.array(axes, dtype=np.int64), np.array(faces, dtype=np.int64),
            np.array(far, dtype=np.int64), np.array(tets, dtype=np.int64))


_OFFSETS, _PATH_IDX, _AXES, _FACE_IDX, _FACE_FAR, _FACE_TETS = _tables()


def _kernel_tables(h):
    """What the kernels read at run time: the point offsets, tetrahedron paths and axes
    (intrinsic operator) and each face's |u_b x v_b|^2, the squared doubled area of its
    base triangle with the spacing folded in (weighted operator). The rest of the face
    geometry is written into the generated stencil."""
    base = _OFFSETS * h
    p0 = base[_FACE_IDX[:, 0]]
    ub, vb = base[_FACE_IDX[:, 1]] - p0, base[_FACE_IDX[:, 2]] - p0
    cross2 = (np.cross(ub, vb) ** 2).sum(axis=1)
    return (_OFFSETS, _PATH_IDX, _AXES, cross2)
