"""The paper's six test functions on [-1, 1]^3 with exact derivatives and mean curvature.

Each function comes with closed-form gradient and Hessian (no finite differences),
and `mean_curvature` gives the exact H of its graph with upward normal
(docs/design.md section 2): ``H = -[(1 + |g|^2) tr(Hf) - g^T Hf g] / (n W^3)``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "TestFunction", "FUNCTIONS", "functions", "graph_mean_curvature", "normalized_rms_error",
    "implicit_mean_curvature", "derivatives", "Hypersurface", "HYPERSURFACES",
]


@dataclass(frozen=True)
class TestFunction:
    """A function of (x, y, z) with its exact gradient and Hessian."""

    name: str
    formula: str
    value: Callable
    gradient: Callable  # -> (..., 3)
    hessian: Callable  # -> (..., 3, 3)

    def __call__(self, x, y, z):
        """The function's values at the points (x, y, z)."""
        return self.value(x, y, z)

    def mean_curvature(self, x, y, z) -> NDArray[np.float64]:
        """Exact mean curvature of the graph (upward normal) at (x, y, z)."""
        return graph_mean_curvature(self.gradient(x, y, z), self.hessian(x, y, z))


def graph_mean_curvature(gradient, hessian) -> NDArray[np.float64]:
    """H of the graph of f over R^n from its gradient (..., n) and Hessian (..., n, n)."""
    g = np.asarray(gradient, dtype=np.float64)
    h = np.asarray(hessian, dtype=np.float64)
    n = g.shape[-1]
    g2 = np.einsum("...i,...i->...", g, g)
    trace = np.trace(h, axis1=-2, axis2=-1)
    ghg = np.einsum("...i,...ij,...j->...", g, h, g)
    return -((1 + g2) * trace - ghg) / (n * (1 + g2) ** 1.5)


def _stack(*components):
    arrays = np.broadcast_arrays(*[np.asarray(c, dtype=np.float64) for c in components])
    return np.stack(arrays, axis=-1)


def _hess(xx, xy, xz, yy, yz, zz):
    xx, xy, xz, yy, yz, zz = np.broadcast_arrays(
        *[np.asarray(c, dtype=np.float64) for c in (xx, xy, xz, yy, yz, zz)]
    )
    row0, row1, row2 = _stack(xx, xy, xz), _stack(xy, yy, yz), _stack(xz, yz, zz)
    return np.stack([row0, row1, row2], axis=-2)


def functions(cubic_sign: float = -1.0) -> dict[str, TestFunction]:
    """The six functions of docs/design.md section 7, keyed by short name.

    Parameters
    ----------
    cubic_sign : float
        Sign of the cubic's ``x z^2`` term, lost in the paper's text;
        ``-1`` (default) reads it as ``0.15 (x^3 + 2 x^2 y - x z^2 + 2 y^2)``.
    """
    c = float(cubic_sign)
    pi = np.pi
    zero = 0.0
    fs = [
        TestFunction(
            "quadratic_sum", "0.4(x^2+y^2+z^2)",
            lambda x, y, z: 0.4 * (x * x + y * y + z * z),
            lambda x, y, z: _stack(0.8 * x, 0.8 * y, 0.8 * z),
            lambda x, y, z: _hess(0.8 + 0 * x, zero, zero, 0.8, zero, 0.8),
        ),
        TestFunction(
            "quadratic_saddle", "0.4(x^2-y^2-z^2)",
            lambda x, y, z: 0.4 * (x * x - y * y - z * z),
            lambda x, y, z: _stack(0.8 * x, -0.8 * y, -0.8 * z),
            lambda x, y, z: _hess(0.8 + 0 * x, zero, zero, -0.8, zero, -0.8),
        ),
        TestFunction(
            "cubic", f"0.15(x^3+2x^2y{'-' if c < 0 else '+'}xz^2+2y^2)",
            lambda x, y, z: 0.15 * (x**3 + 2 * x * x * y + c * x * z * z + 2 * y * y),
            lambda x, y, z: _stack(
                0.15 * (3 * x * x + 4 * x * y + c * z * z),
                0.15 * (2 * x * x + 4 * y),
                0.15 * (2 * c * x * z),
            ),
            lambda x, y, z: _hess(
                0.15 * (6 * x + 4 * y), 0.15 * 4 * x, 0.15 * 2 * c * z,
                0.15 * 4 + 0 * x, zero, 0.15 * 2 * c * x,
            ),
        ),
        TestFunction(
            "exponential", "exp(-0.5(x^2+y^2+z^2))",
            lambda x, y, z: np.exp(-0.5 * (x * x + y * y + z * z)),
            lambda x, y, z: -_stack(x, y, z) * np.exp(-0.5 * (x * x + y * y + z * z))[..., None],
            lambda x, y, z: (
                np.exp(-0.5 * (x * x + y * y + z * z))[..., None, None]
                * (np.einsum("...i,...j->...ij", _stack(x, y, z), _stack(x, y, z))
                   - np.eye(3))
            ),
        ),
        TestFunction(
            "cosine", "0.1(cos(pi x)+cos(pi y)+cos(pi z))",
            lambda x, y, z: 0.1 * (np.cos(pi * x) + np.cos(pi * y) + np.cos(pi * z)),
            lambda x, y, z: -0.1 * pi * _stack(np.sin(pi * x), np.sin(pi * y), np.sin(pi * z)),
            lambda x, y, z: _hess(
                -0.1 * pi * pi * np.cos(pi * x), zero, zero,
                -0.1 * pi * pi * np.cos(pi * y), zero, -0.1 * pi * pi * np.cos(pi * z),
            ),
        ),
        TestFunction(
            "sine", "sin(pi x)+sin(pi y)+sin(pi z)",
            lambda x, y, z: np.sin(pi * x) + np.sin(pi * y) + np.sin(pi * z),
            lambda x, y, z: pi * _stack(np.cos(pi * x), np.cos(pi * y), np.cos(pi * z)),
            lambda x, y, z: _hess(
                -pi * pi * np.sin(pi * x), zero, zero,
                -pi * pi * np.sin(pi * y), zero, -pi * pi * np.sin(pi * z),
            ),
        ),
    ]
    return {f.name: f for f in fs}


#: The six functions with the default reading of the cubic.
FUNCTIONS = functions()


def normalized_rms_error(estimate, exact, mask=None) -> float:
    """RMS of (estimate - exact) over `mask` (default: where the estimate is finite),
    divided by the range max - min of the exact values there (docs/design.md section 7)."""
    estimate, exact = np.asarray(estimate, float), np.asarray(exact, float)
    mask = np.isfinite(estimate) if mask is None else np.asarray(mask, bool) & np.isfinite(estimate)
    if not mask.any():
        raise ValueError("no vertices to measure the error over")
    spread = float(exact[mask].max() - exact[mask].min())
    rms = float(np.sqrt(np.mean((estimate[mask] - exact[mask]) ** 2)))
    return rms / spread if spread > 0 else rms


# ---------------------------------------------------------------- implicit hypersurfaces


def implicit_mean_curvature(gradient, hessian) -> NDArray[np.float64]:
    """H of the level set of F through a point, normal toward lower F (docs/design.md section 11).

    ``H = -[|g|^2 tr(Hess) - g^T Hess g] / (n |g|^3)`` with g = grad F, n = dim - 1:
    +1/r on the sphere ``F = -|p|^2``; for ``F = f(x) - y`` it is the graph formula.

    Parameters
    ----------
    gradient : (..., d) array_like
    hessian : (..., d, d) array_like
    """
    g = np.asarray(gradient, dtype=np.float64)
    h = np.asarray(hessian, dtype=np.float64)
    n = g.shape[-1] - 1
    g2 = np.einsum("...i,...i->...", g, g)
    trace = np.trace(h, axis1=-2, axis2=-1)
    ghg = np.einsum("...i,...ij,...j->...", g, h, g)
    return -(g2 * trace - ghg) / (n * g2 ** 1.5)


def derivatives(function, points, step: float = 1e-3) -> tuple:
    """Gradient (P, d) and Hessian (P, d, d) of ``function(points (P, d)) -> (P,)`` by
    fourth-order central differences (error about step^4 times the fifth derivatives:
    below 1e-9 for the smooth test hypersurfaces, checked against closed forms)."""
    points = np.asarray(points, dtype=np.float64)
    d = points.shape[1]
    unit = np.eye(d) * step

    def f(*shifts):
        return function(points + sum(shifts, np.zeros(d)))

    gradient = np.stack([(8 * (f(unit[a]) - f(-unit[a])) - (f(2 * unit[a]) - f(-2 * unit[a])))
                         / (12 * step) for a in range(d)], axis=-1)
    hessian = np.empty((len(points), d, d))
    centre = f()
    for a in range(d):
        hessian[:, a, a] = (-f(2 * unit[a]) + 16 * f(unit[a]) - 30 * centre + 16 * f(-unit[a])
                            - f(-2 * unit[a])) / (12 * step * step)
        for b in range(a + 1, d):
            def mixed(k, a=a, b=b):
                return (f(k * unit[a], k * unit[b]) - f(k * unit[a], -k * unit[b])
                        - f(-k * unit[a], k * unit[b]) + f(-k * unit[a], -k * unit[b]))
            hessian[:, a, b] = hessian[:, b, a] = (16 * mixed(1) - mixed(2)) / (48 * step * step)
    return gradient, hessian


@dataclass(frozen=True)
class Hypersurface:
    """A test hypersurface ``{F = level}`` in R^4 (normal toward lower F)."""

    name: str
    formula: str
    field: Callable     # (P, 4) -> (P,)
    level: float

    def sample(self, resolution: int, lo: float = -1.0, hi: float = 1.0) -> tuple:
        """(F on a resolution^4 grid over [lo, hi]^4, grid step)."""
        axis = np.linspace(lo, hi, resolution)
        grid = np.stack(np.meshgrid(*[axis] * 4, indexing="ij"), axis=-1)
        return self.field(grid.reshape(-1, 4)).reshape((resolution,) * 4), axis[1] - axis[0]

    def mean_curvature(self, points) -> NDArray[np.float64]:
        """Exact H at points on (or next to) the hypersurface."""
        return implicit_mean_curvature(*derivatives(self.field, points))


def _s1_x_s2(p, big=0.55, small=0.28):
    ring = np.hypot(p[:, 0], p[:, 1])
    return -((ring - big) ** 2 + p[:, 2] ** 2 + p[:, 3] ** 2) / small ** 2


def _moving_blob(p):
    t = p[:, 3]
    centre = 0.3 * np.sin(0.5 * np.pi * t)
    radius = 0.5 + 0.12 * t
    return -((p[:, 0] - centre) ** 2 + p[:, 1] ** 2 + p[:, 2] ** 2) / radius ** 2


HYPERSURFACES = {
    "sphere": Hypersurface("sphere", "-|p|^2 = -0.6^2 (H = 1/0.6)",
                           lambda p: -np.einsum("ij,ij->i", p, p), -0.36),
    "ellipsoid": Hypersurface("ellipsoid", "-(x^2/0.8^2 + y^2/0.6^2 + z^2/0.5^2 + w^2/0.4^2) = -1",
                              lambda p: -((p / [0.8, 0.6, 0.5, 0.4]) ** 2).sum(axis=1), -1.0),
    "s1_x_s2": Hypersurface("s1_x_s2", "-((sqrt(x^2+y^2) - 0.55)^2 + z^2 + w^2) / 0.28^2 = -1",
                            _s1_x_s2, -1.0),
    "moving_blob": Hypersurface(
        "moving_blob", "sphere of radius 0.5 + 0.12 t centred at x = 0.3 sin(pi t / 2), t = w",
        _moving_blob, -1.0),
}
