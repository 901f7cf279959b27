"""The paper's six test functions on [-1, 1]^3 with exact derivatives and mean curvature.

Each function comes with closed-form gradient and Hessian (no finite differences),
and `mean_curvature` gives the exact H of its graph with upward normal
(DESIGN.md section 2): ``H = -[(1 + |g|^2) tr(Hf) - g^T Hf g] / (n W^3)``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "TestFunction", "FUNCTIONS", "functions", "graph_mean_curvature", "normalized_rms_error",
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
    """The six functions of DESIGN.md section 7, keyed by short name.

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
    divided by the range max - min of the exact values there (DESIGN.md section 7)."""
    estimate, exact = np.asarray(estimate, float), np.asarray(exact, float)
    mask = np.isfinite(estimate) if mask is None else np.asarray(mask, bool) & np.isfinite(estimate)
    if not mask.any():
        raise ValueError("no vertices to measure the error over")
    spread = float(exact[mask].max() - exact[mask].min())
    rms = float(np.sqrt(np.mean((estimate[mask] - exact[mask]) ** 2)))
    return rms / spread if spread > 0 else rms
