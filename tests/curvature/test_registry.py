"""The operator registry is the one list of operators: every consumer reads it."""

import numpy as np
import pytest

from volseg import tessellation
from volseg.curvature import (
    OPERATORS,
    REGISTRY,
    cli_choices,
    get_operator,
    grid_curvature,
    normalize_operator,
    vertex_curvature,
)


def test_names_aliases_and_errors():
    assert OPERATORS == tuple(REGISTRY)
    for name, entry in REGISTRY.items():
        assert normalize_operator(name.upper()) == name
        assert normalize_operator(name.replace("_", "-")) == name
        for alias in entry.aliases:
            assert get_operator(alias) is entry
    assert normalize_operator("LB") == "laplace_beltrami"
    with pytest.raises(ValueError, match="unknown `operator` 'gaussian'; choose one of weighted"):
        normalize_operator("gaussian")


def test_every_command_line_choice_resolves_and_the_shown_names_are_hyphenated():
    accepted, shown = cli_choices()
    assert {normalize_operator(a) for a in accepted} == set(REGISTRY)
    assert shown == "{weighted,unweighted,laplace-beltrami,intrinsic}"


@pytest.mark.parametrize("name", list(REGISTRY))
def test_every_entry_runs_on_both_paths_and_they_agree(name, rng):
    """The entry's mesh function and its grid kernel + finishing step give the same
    interior values on a small Kuhn graph: nothing about an operator lives elsewhere."""
    field = rng.standard_normal((5, 6, 7))
    vertices, simplices = tessellation.kuhn_grid_mesh(field, value_scale=0.3)
    on_mesh = vertex_curvature(vertices, simplices, name).reshape(field.shape)
    on_grid = grid_curvature(field, name, value_scale=0.3)
    inner = (slice(1, -1),) * 3
    np.testing.assert_allclose(on_grid[inner], on_mesh[inner], rtol=1e-9, atol=1e-11)
    assert REGISTRY[name].label and REGISTRY[name].colour.startswith("tab:")


def test_dimension_limits_come_from_the_entry():
    t = 2 * np.pi * np.arange(16) / 16
    circle = np.c_[np.cos(t), np.sin(t)]
    edges = np.c_[np.arange(16), (np.arange(16) + 1) % 16]
    with pytest.raises(ValueError, match="'intrinsic' operator is defined for n = 2 and n = 3"):
        vertex_curvature(circle, edges, "intrinsic")
