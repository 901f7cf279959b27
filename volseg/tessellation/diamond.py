"""Diamond meshes: adaptive longest-edge bisection of a (2^k + 1)^3 grid (docs/design.md §8).

Weiss and De Floriani's diamond hierarchy: every grid point but the 8 root corners is
the centre of one diamond (the tetrahedra sharing a spine edge, which split together
at its midpoint, so the mesh never cracks). A diamond may split only after all of
its parents have split. `diamond_mesh` splits, from the root down, every diamond
whose tetrahedra interpolate the field worse than `eps` somewhere, and returns the
leaf tetrahedra.
"""

from __future__ import annotations

import functools
import itertools
from dataclasses import dataclass

import numba
import numpy as np
from numpy.typing import NDArray

from .._kuhn import axis_orders
from .irregular import orient_upward

__all__ = ["Diamond", "decode", "diamond_mesh", "DiamondMesh", "interpolation_error"]


@dataclass(frozen=True)
class Diamond:
    """The diamond centred at grid point `centre` of a grid with side N."""

    centre: tuple
    n: int
    scale: int  # a
    kind: int  # class 0, 1, 2
    spine: tuple  # (p0, p1)
    odd: tuple  # axes where centre / a is odd

    def _inside(self, p):
        return 0 <= p[0] <= self.n and 0 <= p[1] <= self.n and 0 <= p[2] <= self.n

    def _raw_tetrahedra(self) -> list:
        """The unclipped tetrahedra, as lists of 4 integer 3-tuples (plain Python: this
        runs once per diamond in the extraction loop)."""
        v, a = self.centre, self.scale
        p0, p1 = self.spine
        moved = _moved
        out = []
        if self.kind == 0:
            step = [2 * a * ((p1[i] > p0[i]) - (p1[i] < p0[i])) for i in range(3)]
            for perm in axis_orders(3):
                path = [p0]
                for axis in perm:
                    path.append(moved(path[-1], axis, step[axis]))
                out.append(path)
        elif self.kind == 1:
            normal = next(i for i in range(3) if i not in self.odd)
            i, j = self.odd
            corners = [moved(moved(v, i, s * a), j, t * a) for s in (-1, 1) for t in (-1, 1)]
            for q in corners:
                if q in (p0, p1):
                    continue
                for s in (-1, 1):
                    out.append([p0, p1, q, moved(v, normal, s * a)])
        else:
            even = [i for i in range(3) if i not in self.odd]
            for j, k in (even, even[::-1]):
                for s in (-1, 1):
                    q = moved(v, j, s * a)
                    for t in (-1, 1):
                        out.append([p0, p1, q, moved(q, k, t * a)])
        return out

    def tetrahedra_array(self) -> NDArray[np.int64]:
        """(m, 4, 3) grid points of the diamond's tetrahedra, clipped to the domain."""
        tets = np.array(self._raw_tetrahedra(), dtype=np.int64)
        return tets[((tets >= 0) & (tets <= self.n)).all(axis=(1, 2))]

    def tetrahedra(self) -> list[tuple]:
        """The diamond's tetrahedra (4 grid points each), clipped to the domain."""
        return [tet for tet in map(tuple, self._raw_tetrahedra())
                if all(self._inside(p) for p in tet)]

    def parents(self) -> list[tuple]:
        """The centres of the diamonds that must split before this one."""
        v, a = self.centre, self.scale
        if self.kind == 0:
            if a == self.n // 2:
                return []
            out = []
            for s in itertools.product((-1, 1), repeat=3):
                p = (v[0] + a * s[0], v[1] + a * s[1], v[2] + a * s[2])
                if sum((c // (2 * a)) % 2 == 1 and c % (2 * a) == 0 for c in p) == 1:
                    out.append(p)
        elif self.kind == 1:
            normal = next(i for i in range(3) if i not in self.odd)
            out = [_moved(v, normal, s * a) for s in (-1, 1)]
        else:
            even = [i for i in range(3) if i not in self.odd]
            out = [_moved(v, j, s * a) for j in even for s in (-1, 1)]
        return [p for p in out if self._inside(p)]

    def children(self) -> list[tuple]:
        """The centres of the diamonds this one's split creates."""
        v, a = self.centre, self.scale
        if self.kind == 0:
            out = [_moved(v, i, s * a) for i in range(3) for s in (-1, 1)]
        elif self.kind == 1:
            out = [_moved(v, i, s * a) for i in self.odd for s in (-1, 1)]
        else:
            if a == 1:
                return []
            h = a // 2
            out = [(v[0] + h * s[0], v[1] + h * s[1], v[2] + h * s[2])
                   for s in itertools.product((-1, 1), repeat=3)]
        return [p for p in out if self._inside(p)]


def _moved(p, axis, amount):
    q = list(p)
    q[axis] += amount
    return tuple(q)


def decode(centre, n: int) -> Diamond:
    """The diamond centred at grid point `centre` of the grid {0..n}^3 (n a power of 2)."""
    v = tuple(int(c) for c in centre)
    nonzero = [c for c in v if c]
    if all(c in (0, n) for c in v):
        raise ValueError(f"{v} is a corner of the root cube, not the centre of a diamond")
    a = 1
    while all(c % (2 * a) == 0 for c in nonzero):
        a *= 2
    odd = tuple(i for i in range(3) if (v[i] // a) % 2 == 1)
    kind = 3 - len(odd)
    d = [0, 0, 0]
    for i in odd:
        d[i] = -1 if (v[i] // a) % 4 == 1 else 1
    p0 = tuple(v[i] - a * d[i] for i in range(3))
    p1 = tuple(v[i] + a * d[i] for i in range(3))
    return Diamond(v, n, a, kind, (p0, p1), odd)


@dataclass
class DiamondMesh:
    """Leaf tetrahedra of an extracted diamond mesh.

    Attributes
    ----------
    grid : (V, 3) ndarray of int
        Grid coordinates in {0..N}^3 of the mesh vertices.
    points : (V, 3) ndarray of float
        The same in [-1, 1]^3.
    tetrahedra : (T, 4) ndarray of intp
        Upward-oriented (see `orient_upward`).
    split : (N+1, N+1, N+1) ndarray of bool
        Which diamonds (by centre) were split.
    n : int
    """

    grid: NDArray[np.int64]
    points: NDArray[np.float64]
    tetrahedra: NDArray[np.intp]
    split: NDArray[np.bool_]
    n: int


def interpolation_error(values, tetrahedra) -> float:
    """Max |f - linear interpolant| over the grid samples inside (or on) the tetrahedra.

    `tetrahedra` is (m, 4, 3) grid coordinates (for a `DiamondMesh`,
    ``mesh.grid[mesh.tetrahedra]``): the error bound `diamond_mesh` promises.
    """
    tets = np.ascontiguousarray(tetrahedra, dtype=np.int64).reshape(-1, 4, 3)
    return float(_tets_error(np.asarray(values, dtype=np.float64), tets))


@numba.njit(cache=True, nogil=True)
def _tets_error(values, tets):
    """Max over tetrahedra (m, 4, 3) of |f - linear interpolant| at the grid samples
    inside or on each (barycentric coordinates >= -1e-9)."""
    worst = 0.0
    for t in range(tets.shape[0]):
        c = tets[t].astype(np.float64)
        m = np.empty((3, 3))
        for i in range(3):
            for j in range(3):
                m[i, j] = c[j + 1, i] - c[0, i]
        inverse = np.linalg.inv(m)
        lo = np.empty(3, dtype=np.int64)
        hi = np.empty(3, dtype=np.int64)
        for i in range(3):
            lo[i] = tets[t, :, i].min()
            hi[i] = tets[t, :, i].max()
        f0 = values[tets[t, 0, 0], tets[t, 0, 1], tets[t, 0, 2]]
        df = np.empty(3)
        for k in range(3):
            df[k] = values[tets[t, k + 1, 0], tets[t, k + 1, 1], tets[t, k + 1, 2]] - f0
        for x in range(lo[0], hi[0] + 1):
            for y in range(lo[1], hi[1] + 1):
                for z in range(lo[2], hi[2] + 1):
                    r0, r1, r2 = x - c[0, 0], y - c[0, 1], z - c[0, 2]
                    b1 = inverse[0, 0] * r0 + inverse[0, 1] * r1 + inverse[0, 2] * r2
                    b2 = inverse[1, 0] * r0 + inverse[1, 1] * r1 + inverse[1, 2] * r2
                    b3 = inverse[2, 0] * r0 + inverse[2, 1] * r1 + inverse[2, 2] * r2
                    if b1 < -1e-9 or b2 < -1e-9 or b3 < -1e-9 or b1 + b2 + b3 > 1 + 1e-9:
                        continue
                    interpolated = f0 + b1 * df[0] + b2 * df[1] + b3 * df[2]
                    err = abs(values[x, y, z] - interpolated)
                    if err > worst:
                        worst = err
    return worst


def _longest_edge_bisect(tetrahedra, split):
    """Bisect every tetrahedron whose longest-edge midpoint is a split diamond, until
    none is; returns the leaves (rows of 4 grid points, integer coordinates)."""
    leaves = []
    pending = np.asarray(tetrahedra, dtype=np.int64)  # (T, 4, 3)
    pairs = list(itertools.combinations(range(4), 2))
    while len(pending):
        lengths = np.stack([np.sum((pending[:, i] - pending[:, j]) ** 2, axis=1)
                            for i, j in pairs], axis=1)
        longest = np.argmax(lengths, axis=1)
        i_idx = np.array([p[0] for p in pairs])[longest]
        j_idx = np.array([p[1] for p in pairs])[longest]
        rows = np.arange(len(pending))
        p0, p1 = pending[rows, i_idx], pending[rows, j_idx]
        total = p0 + p1
        integral = np.all(total % 2 == 0, axis=1)
        middle = total // 2
        go = integral.copy()
        go[integral] = split[tuple(middle[integral].T)]
        leaves.append(pending[~go])
        if not go.any():
            break
        pending, p0, p1, middle = pending[go], p0[go], p1[go], middle[go]
        i_idx, j_idx = i_idx[go], j_idx[go]
        rest = np.array([[k for k in range(4) if k not in (i, j)]
                         for i, j in zip(i_idx, j_idx, strict=True)])
        rows = np.arange(len(pending))
        q0, q1 = pending[rows, rest[:, 0]], pending[rows, rest[:, 1]]
        first = np.stack([p0, middle, q0, q1], axis=1)
        second = np.stack([p1, middle, q0, q1], axis=1)
        pending = np.concatenate([first, second])
    return np.concatenate(leaves) if leaves else np.zeros((0, 4, 3), dtype=np.int64)


def diamond_mesh(values, eps: float) -> DiamondMesh:
    """Extract the diamond mesh of a (2^k+1)^3 field for interpolation error `eps`.

    Parameters
    ----------
    values : (N+1, N+1, N+1) array_like of float
        Samples on the grid {0..N}^3, N = 2^k, mapped to [-1, 1]^3.
    eps : float
        A diamond splits when the field deviates by more than `eps` from the linear
        interpolant of one of its tetrahedra at a grid sample inside it. Negative:
        every diamond splits (the full-resolution reflected Kuhn grid).

    Returns
    -------
    DiamondMesh
        Every leaf tetrahedron interpolates the samples inside it within `eps`.
    """
    values = np.asarray(values, dtype=np.float64)
    n = values.shape[0] - 1
    if values.ndim != 3 or len(set(values.shape)) != 1 or n < 2 or n & (n - 1):
        raise ValueError(f"`values` must be (2^k+1)^3 with k >= 1, got shape {values.shape}")
    split = np.zeros(values.shape, dtype=bool)
    root = (n // 2,) * 3
    diamond = functools.lru_cache(maxsize=None)(lambda centre: decode(centre, n))

    def error(centre):
        if eps < 0:
            return np.inf
        return _tets_error(values, diamond(centre).tetrahedra_array())

    def split_closure(centre):
        stack = [centre]
        while stack:  # split parents first, then the diamond (recursive closure)
            top = stack[-1]
            if split[top]:
                stack.pop()
                continue
            waiting = [p for p in diamond(top).parents() if not split[p]]
            if waiting:
                stack.extend(waiting)
                continue
            split[top] = True
            stack.pop()
            queue.extend(diamond(top).children())

    queue = [root]
    while queue:
        centre = queue.pop()
        if not split[centre] and error(centre) > eps:
            split_closure(centre)
    root_tets = decode(root, n).tetrahedra()
    leaves = _longest_edge_bisect(np.array(root_tets, dtype=np.int64), split)
    grid, inverse = np.unique(leaves.reshape(-1, 3), axis=0, return_inverse=True)
    tetrahedra = inverse.reshape(-1, 4).astype(np.intp)
    points = -1.0 + 2.0 * grid / n
    return DiamondMesh(grid, points, orient_upward(points, tetrahedra), split, n)
