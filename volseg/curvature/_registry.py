"""The curvature operators, one entry each: every list of operators reads this table.

An entry says how the operator is named (and its aliases), how it is computed on an
explicit mesh (a function of `MeshParts`), for which dimensions n and whether it needs
a consistent orientation, and how the grid path computes it: the kernel's inner-work
code, the accumulator channels and the finishing step. The CLI's and pipelines'
choices, the figures' colours and labels and the parametrised tests are derived from
it. Adding an operator: one entry here, one mesh function, one compiled pass in
`_grid_kernels._PASSES` with its finishing step in `_grid_finish`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from . import _grid_finish
from ._extrinsic import unweighted_distortion, weighted_distortion
from ._intrinsic import intrinsic_distortion
from ._laplace import laplace_beltrami

__all__ = ["Operator", "REGISTRY", "OPERATORS", "get_operator", "normalize_operator",
           "cli_choices"]


@dataclass(frozen=True)
class Operator:
    name: str
    label: str                    # for figures and messages
    colour: str                   # matplotlib colour in figures
    aliases: tuple[str, ...]
    mesh: Callable                # f(MeshParts) -> (V,) values
    dimensions: tuple[int, ...] | None   # n it is defined for; None: any n >= 1
    oriented: bool                # needs a consistently oriented mesh
    grid_code: int                # which pass of `_grid_kernels._PASSES` runs
    grid_channels: int            # accumulator channels of that work
    grid_finish: Callable         # f(acc, inner, spacing) -> (X, Y, Z) values
    summary: str


REGISTRY = {op.name: op for op in [
    Operator("weighted", "weighted distortion", "tab:blue", (),
             weighted_distortion, None, True, 0, 2, _grid_finish.weighted,
             "the paper's mean-curvature estimate, sum psi |tau| / (n^2 |p|)"),
    Operator("unweighted", "unweighted distortion", "tab:green", ("distortion",),
             unweighted_distortion, None, True, 1, 2, _grid_finish.unweighted,
             "extrinsic distortion, sum psi, radians"),
    Operator("laplace_beltrami", "Laplace-Beltrami", "tab:red",
             ("laplace-beltrami", "lb", "cotangent"),
             laplace_beltrami, None, True, 2, 9, _grid_finish.laplace_beltrami,
             "cotangent mean curvature sign(K . nu) |K| / n"),
    Operator("intrinsic", "intrinsic distortion", "tab:purple", (),
             intrinsic_distortion, (2, 3), False, 3, 2, _grid_finish.intrinsic,
             "angle (n = 2) or solid-angle (n = 3) deficit"),
]}
OPERATORS = tuple(REGISTRY)
_BY_ALIAS = {alias: op for op in REGISTRY.values() for alias in (op.name, *op.aliases)}
GRID_CODES = {op.name: op.grid_code for op in REGISTRY.values()}


def get_operator(operator: str | Operator) -> Operator:
    """The registry entry of an operator name or alias (case-insensitive)."""
    if isinstance(operator, Operator):
        return operator
    entry = _BY_ALIAS.get(str(operator).lower())
    if entry is None:
        raise ValueError(f"unknown `operator` {operator!r}; choose one of {', '.join(OPERATORS)}")
    return entry


def normalize_operator(operator: str) -> str:
    """Canonical operator name; accepts hyphens and a few aliases."""
    return get_operator(operator).name


def cli_choices() -> tuple[list[str], str]:
    """What a command line accepts (hyphenated names, canonical names, aliases) and the
    metavar that shows the hyphenated names only."""
    shown = [op.name.replace("_", "-") for op in REGISTRY.values()]
    return list(dict.fromkeys([*shown, *_BY_ALIAS])), "{" + ",".join(shown) + "}"
