"""Compiled pass for `volseg.mesh.pinched_vertices`: is each vertex's star in one piece?"""

import numba
import numpy as np

from ._union_find import find_root


@numba.njit(cache=True, nogil=True)
def star_pieces(simplices, face_owner, face_opposite, n_vertices, pieces):
    """pieces[v] = 1 if v's star is connected, 2 if it is in two or more pieces, 0 if unused.

    Node s * width + c is simplex s at its local vertex c. Each interior face (owners
    face_owner[f, 0..1], opposite local vertices face_opposite[f, 0..1]) joins its two
    simplices at every vertex it has; union-find over the nodes, then each vertex
    checks that all its nodes share one root.
    """
    n_simplices, width = simplices.shape
    parent = np.arange(n_simplices * width)
    for f in range(face_owner.shape[0]):
        sa, sb = face_owner[f, 0], face_owner[f, 1]
        ca, cb = face_opposite[f, 0], face_opposite[f, 1]
        for i in range(width):
            if i == ca:
                continue
            v = simplices[sa, i]
            for j in range(width):
                if j != cb and simplices[sb, j] == v:
                    ra = find_root(parent, sa * width + i)
                    rb = find_root(parent, sb * width + j)
                    if ra != rb:
                        parent[ra] = rb
                    break
    root = np.full(n_vertices, -1, dtype=np.int64)
    for node in range(n_simplices * width):
        v = simplices[node // width, node % width]
        r = find_root(parent, node)
        if root[v] < 0:
            root[v] = r
            pieces[v] = 1
        elif root[v] != r:
            pieces[v] = 2
