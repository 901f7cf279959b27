"""The six analytic functions, their exact curvature, grid convergence, the pipeline."""

import csv

import numpy as np
import pytest

from pipelines import analytic as pipeline
from volseg.analytic import FUNCTIONS, functions, graph_mean_curvature, normalized_rms_error
from volseg.curvature import grid_curvature


def _points(rng, n=25):
    return rng.uniform(-0.9, 0.9, size=(3, n))


@pytest.mark.parametrize("name", sorted(FUNCTIONS))
def test_exact_derivatives_match_finite_differences(name, rng):
    f = FUNCTIONS[name]
    x, y, z = _points(rng)
    h = 1e-5
    steps = np.eye(3) * h
    fd_gradient = np.stack([(f(*(np.array([x, y, z]) + s[:, None])) -
                             f(*(np.array([x, y, z]) - s[:, None]))) / (2 * h)
                            for s in steps], axis=-1)
    np.testing.assert_allclose(f.gradient(x, y, z), fd_gradient, atol=1e-7)
    fd_hessian = np.stack([(f.gradient(*(np.array([x, y, z]) + s[:, None])) -
                            f.gradient(*(np.array([x, y, z]) - s[:, None]))) / (2 * h)
                           for s in steps], axis=-1)
    np.testing.assert_allclose(f.hessian(x, y, z), fd_hessian, atol=1e-6)
    # Mean curvature from second differences of the values alone.
    h = 1e-3
    point = np.array([x, y, z])
    values = {}

    def at(*offsets):
        key = tuple(offsets)
        if key not in values:
            values[key] = f(*(point + np.array(offsets)[:, None] * h))
        return values[key]

    g = np.stack([(at(*e) - at(*-e)) / (2 * h) for e in np.eye(3)], axis=-1)
    hess = np.empty(x.shape + (3, 3))
    for i in range(3):
        for j in range(3):
            ei, ej = np.eye(3)[i], np.eye(3)[j]
            hess[:, i, j] = (at(*(ei + ej)) - at(*(ei - ej)) - at(*(ej - ei))
                             + at(*(-ei - ej))) / (4 * h * h)
    np.testing.assert_allclose(f.mean_curvature(x, y, z), graph_mean_curvature(g, hess), atol=1e-5)


def test_mean_curvature_sign_and_a_hand_value():
    f = FUNCTIONS["quadratic_sum"]  # a bowl: negative with upward normals
    assert f.mean_curvature(0.0, 0.0, 0.0) == pytest.approx(-0.8)
    assert FUNCTIONS["exponential"].mean_curvature(0.0, 0.0, 0.0) == pytest.approx(1.0)  # a peak
    # The cubic's lost sign is a parameter and it matters.
    a, b = functions(-1.0)["cubic"], functions(1.0)["cubic"]
    assert "-xz^2" in a.formula and "+xz^2" in b.formula
    assert a.mean_curvature(0.5, 0.1, 0.7) != pytest.approx(b.mean_curvature(0.5, 0.1, 0.7))


def test_normalized_rms_error():
    exact = np.array([0.0, 1.0, 2.0, 4.0])
    assert normalized_rms_error(exact + 0.4, exact) == pytest.approx(0.1)
    assert normalized_rms_error(np.array([np.nan, 1, 2, 4.4]), exact) == pytest.approx(
        np.sqrt(0.16 / 3) / 3)
    with pytest.raises(ValueError):
        normalized_rms_error(np.full(4, np.nan), exact)


@pytest.mark.parametrize("operator", ["weighted", "laplace_beltrami"])
def test_both_operators_converge_at_second_order_on_grids(operator):
    resolutions = [9, 17, 33]
    errors = []
    for resolution in resolutions:
        axis = np.linspace(-1, 1, resolution)
        x, y, z = np.meshgrid(axis, axis, axis, indexing="ij")
        h = 2 / (resolution - 1)
        inner = (slice(1, -1),) * 3
        per_function = []
        for f in FUNCTIONS.values():
            estimate = grid_curvature(f(x, y, z), operator, spacing=(h, h, h), value_scale=1.0)
            exact = f.mean_curvature(x, y, z)
            per_function.append(normalized_rms_error(estimate[inner], exact[inner]))
        errors.append(np.mean(per_function))
    spacing = [2 / (r - 1) for r in resolutions]
    slope = np.polyfit(np.log(spacing), np.log(errors), 1)[0]
    assert 1.8 < slope < 2.3


@pytest.mark.slow
def test_quick_pipeline_writes_tables_figures_and_the_grid_reduction(tmp_path):
    assert pipeline.main(["--out", str(tmp_path), "--quick", "-q"]) == 0
    for name in ["errors.csv", "summary.csv", "fig2.png", "fig3.png", "reduction.txt"]:
        assert (tmp_path / name).stat().st_size > 0
    with open(tmp_path / "errors.csv") as file:
        rows = list(csv.DictReader(file))
    kinds = {(r["experiment"], r["tessellation"]) for r in rows}
    assert kinds == {("resolution", "grid"), ("resolution", "irregular"),
                     ("resolution", "diamond"), ("valence", "irregular"),
                     ("value_noise", "grid"), ("normal_noise", "grid")}
    assert {r["function"] for r in rows} == set(FUNCTIONS)
    assert {r["operator"] for r in rows} == {"weighted", "laplace_beltrami"}
    with open(tmp_path / "summary.csv") as file:
        summary = list(csv.DictReader(file))
    grid = {(int(s["resolution"]), s["operator"]): float(s["error"]) for s in summary
            if s["experiment"] == "resolution" and s["tessellation"] == "grid"}
    # The paper's claim on uniform grids holds here at every resolution.
    for resolution in pipeline.QUICK.grid_resolutions:
        assert grid[(resolution, "weighted")] < grid[(resolution, "laplace_beltrami")]
    # Noise-free rows of the noise experiments equal the plain grid error there.
    clean = [float(s["error"]) for s in summary
             if s["experiment"] == "value_noise" and float(s["noise_percent"]) == 0
             and s["operator"] == "weighted"]
    assert clean[0] == pytest.approx(grid[(pipeline.QUICK.noise_resolution, "weighted")])
    text = (tmp_path / "reduction.txt").read_text()
    assert "33^3" in text and "%" in text
    import matplotlib.image

    for name in ["fig2.png", "fig3.png"]:
        image = matplotlib.image.imread(tmp_path / name)
        assert image.shape[0] > 300 and image[..., :3].std() > 0.05


def test_implicit_mean_curvature_sphere_graph_and_cylinder():
    import numpy as np

    from volseg.analytic import FUNCTIONS, HYPERSURFACES, derivatives, implicit_mean_curvature

    rng = np.random.default_rng(5)
    points = rng.normal(size=(20, 4))
    points *= 0.6 / np.linalg.norm(points, axis=1, keepdims=True)
    assert np.allclose(HYPERSURFACES["sphere"].mean_curvature(points), 1 / 0.6, rtol=1e-9)
    # Closed form: sphere F = -|p|^2, gradient -2p, Hessian -2I.
    assert np.allclose(implicit_mean_curvature(-2 * points, -2 * np.eye(4)[None].repeat(20, 0)),
                       1 / 0.6)
    # F = f(x) - y reduces to the graph formula (docs/design.md sections 2 and 11).
    for function in FUNCTIONS.values():
        x = rng.uniform(-0.8, 0.8, (15, 3))
        on = np.c_[x, function(*x.T)]
        implicit = implicit_mean_curvature(*derivatives(
            lambda p, f=function: f(p[:, 0], p[:, 1], p[:, 2]) - p[:, 3], on))
        assert np.allclose(implicit, function.mean_curvature(*x.T), atol=1e-8)
    # Cylinder S^1(r) x R^2 with outward normals: H = 1 / (3 r).
    cylinder = np.c_[0.5 * np.cos(np.arange(10)), 0.5 * np.sin(np.arange(10)),
                     rng.normal(size=(10, 2))]
    field = lambda p: -(p[:, 0] ** 2 + p[:, 1] ** 2)  # noqa: E731
    assert np.allclose(implicit_mean_curvature(*derivatives(field, cylinder)), 1 / 1.5, rtol=1e-8)
