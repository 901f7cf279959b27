"""The paper's analytic evaluation (Figs. 2 and 3): curvature error of weighted
distortion vs Laplace-Beltrami on the six test functions of docs/design.md section 7.

    python -m pipelines.analytic --out runs/analytic [--quick]

Writes ``errors.csv`` (one row per function, tessellation, size, operator and
setting), ``summary.csv`` (errors averaged over the six functions), ``fig2.png``
(a: Kuhn grids, b: irregular meshes, c: diamond meshes, d: error by valence),
``fig3.png`` (a: value noise, b: noise along normals) and ``reduction.txt`` (weighted
vs Laplace-Beltrami on grids, per resolution). Files are written atomically.

The error is the RMS of (estimate - exact mean curvature) over interior vertices,
divided by the range of the exact values there, averaged over the functions. Grids
use the Kuhn stencil (`grid_curvature`, equal to the explicit mesh at interior
vertices); irregular and diamond meshes use `vertex_curvature` and, as in the paper,
50 rounds of 1-ring averaging of the estimates (the raw error is in the CSV too).
Error by valence uses the raw estimates on the irregular meshes.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from volseg.curvature import REGISTRY

from ._output import save_figure, write_csv, write_text

OPERATORS = ("weighted", "laplace_beltrami")  # the two the paper's Figs. 2 and 3 compare
SMOOTHING = 50


@dataclass(frozen=True)
class Config:
    grid_resolutions: tuple = (9, 17, 33, 65)
    irregular_vertices: tuple = (729, 4913, 35937, 274625)
    irregular_seeds: tuple = (0, 1)  # the first only above 100 k vertices (Qhull: ~1 min)
    diamond_sides: tuple = (16, 32, 64)
    diamond_eps: tuple = (0.04, 0.02, 0.01, 0.005, 0.0025, 0.001)  # of the function range
    noise_resolution: int = 33
    value_noise: tuple = (0.0, 0.1, 0.25, 0.5, 1.0, 2.0)  # % of the field range
    normal_noise: tuple = (0.0, 1.0, 2.0, 5.0, 10.0, 20.0)  # % of the mean edge length
    noise_seeds: tuple = (0, 1)


QUICK = Config(grid_resolutions=(9, 17, 33), irregular_vertices=(729, 2197),
               irregular_seeds=(0,), diamond_sides=(8, 16), diamond_eps=(0.04, 0.01),
               noise_resolution=17, value_noise=(0.0, 0.5, 2.0), normal_noise=(0.0, 5.0, 20.0),
               noise_seeds=(0,))


def _axis_grid(resolution):
    axis = np.linspace(-1.0, 1.0, resolution)
    return np.meshgrid(axis, axis, axis, indexing="ij")


def _interior_grid(resolution):
    mask = np.zeros((resolution,) * 3, dtype=bool)
    mask[1:-1, 1:-1, 1:-1] = True
    return mask


def grid_errors(functions, resolutions, say):
    from volseg.analytic import normalized_rms_error
    from volseg.curvature import grid_curvature

    rows = []
    for resolution in resolutions:
        x, y, z = _axis_grid(resolution)
        h = 2.0 / (resolution - 1)
        interior = _interior_grid(resolution)
        for name, f in functions.items():
            exact = f.mean_curvature(x, y, z)
            for operator in OPERATORS:
                estimate = grid_curvature(f(x, y, z), operator, spacing=(h, h, h), value_scale=1.0)
                rows.append({"experiment": "resolution", "tessellation": "grid", "function": name,
                             "operator": operator, "size": resolution ** 3,
                             "resolution": resolution,
                             "error": normalized_rms_error(estimate, exact, interior)})
        say(f"grid {resolution}^3 done")
    return rows


def _mesh_rows(tessellation, functions, points, tetrahedra, setting, extra, valence_rows=None):
    """Errors of both operators on one 3-D mesh, for every function."""
    from volseg.analytic import normalized_rms_error
    from volseg.curvature import vertex_curvature
    from volseg.mesh import ring_average
    from volseg.tessellation.irregular import lift

    rows = []
    valence = np.bincount(tetrahedra.ravel(), minlength=len(points))
    for name, f in functions.items():
        vertices = lift(points, f)
        exact = f.mean_curvature(points[:, 0], points[:, 1], points[:, 2])
        for operator in OPERATORS:
            raw = vertex_curvature(vertices, tetrahedra, operator)  # NaN on the boundary
            smooth = ring_average(raw, tetrahedra, SMOOTHING)
            interior = np.isfinite(raw)
            rows.append({"experiment": "resolution", "tessellation": tessellation,
                         "function": name, "operator": operator, "size": len(points),
                         **setting, **extra,
                         "error": normalized_rms_error(smooth, exact, interior),
                         "error_raw": normalized_rms_error(raw, exact, interior)})
            if valence_rows is not None:
                spread = float(np.ptp(exact[interior]))
                for k in np.unique(valence[interior]):
                    at = interior & (valence == k)
                    rms = float(np.sqrt(np.mean((raw[at] - exact[at]) ** 2)))
                    valence_rows.append({"experiment": "valence", "tessellation": tessellation,
                                         "function": name, "operator": operator,
                                         "size": len(points), **setting, "valence": int(k),
                                         "vertices": int(at.sum()), "error": rms / spread})
    return rows


def irregular_errors(functions, sizes, seeds, say):
    from volseg.tessellation.irregular import irregular_cube_mesh

    rows, valence_rows = [], []
    for size in sizes:
        for seed in seeds if size <= 100_000 else seeds[:1]:
            mesh = irregular_cube_mesh(size, seed=seed)
            rows += _mesh_rows("irregular", functions, mesh.points, mesh.tetrahedra,
                               {"seed": seed}, {"tetrahedra": len(mesh.tetrahedra),
                                                "slivers": mesh.slivers}, valence_rows)
            say(f"irregular mesh of {len(mesh.points)} vertices (seed {seed}, "
                f"{mesh.slivers} slivers of {len(mesh.tetrahedra)} tetrahedra) done")
    return rows, valence_rows


def diamond_errors(functions, sides, eps_fractions, say):
    from volseg.tessellation.diamond import diamond_mesh

    rows = []
    for side in sides:
        x, y, z = _axis_grid(side + 1)
        for name, f in functions.items():
            values = f(x, y, z)
            for fraction in eps_fractions:
                eps = fraction * float(np.ptp(values))
                mesh = diamond_mesh(values, eps)
                rows += _mesh_rows("diamond", {name: f}, mesh.points, mesh.tetrahedra,
                                   {"grid_side": side, "eps_fraction": fraction},
                                   {"tetrahedra": len(mesh.tetrahedra)})
        say(f"diamond meshes on the {side + 1}^3 grid done")
    return rows


def noise_errors(functions, resolution, value_levels, normal_levels, seeds, say):
    from volseg.analytic import normalized_rms_error
    from volseg.curvature import grid_curvature, vertex_curvature
    from volseg.noise import add_normal_noise, add_value_noise
    from volseg.tessellation import kuhn_cube_mesh

    rows = []
    x, y, z = _axis_grid(resolution)
    h = 2.0 / (resolution - 1)
    interior = _interior_grid(resolution)
    for name, f in functions.items():
        values = f(x, y, z)
        exact = f.mean_curvature(x, y, z)
        spread = float(np.ptp(values))
        vertices, tetrahedra = kuhn_cube_mesh(resolution, f)
        for seed in seeds:
            rng_entropy = [seed, sum(map(ord, name))]
            for level in value_levels:
                noisy = add_value_noise(values, level, seed=np.random.default_rng(rng_entropy),
                                        reference_range=spread)
                for operator in OPERATORS:
                    estimate = grid_curvature(noisy, operator, spacing=(h, h, h), value_scale=1.0)
                    rows.append({"experiment": "value_noise", "tessellation": "grid",
                                 "function": name, "operator": operator,
                                 "size": resolution ** 3, "resolution": resolution,
                                 "noise_percent": level, "seed": seed,
                                 "error": normalized_rms_error(estimate, exact, interior)})
            for level in normal_levels:
                moved = add_normal_noise(vertices, tetrahedra, level,
                                         seed=np.random.default_rng(rng_entropy),
                                         movable=interior.ravel())
                for operator in OPERATORS:
                    estimate = vertex_curvature(moved, tetrahedra, operator)
                    rows.append({"experiment": "normal_noise", "tessellation": "grid",
                                 "function": name, "operator": operator,
                                 "size": resolution ** 3, "resolution": resolution,
                                 "noise_percent": level, "seed": seed,
                                 "error": normalized_rms_error(estimate, exact.ravel(),
                                                               interior.ravel())})
        say(f"noise on {name} done")
    return rows


# ---------------------------------------------------------------- aggregation and output


def summarize(rows):
    """Errors averaged over functions (and seeds) per experiment, tessellation, size,
    setting and operator; sizes are averaged vertex counts for meshes."""
    groups = {}
    for row in rows:
        setting = tuple((k, row[k]) for k in ("resolution", "grid_side", "eps_fraction",
                                              "noise_percent", "valence") if k in row)
        if row["tessellation"] == "irregular" and row["experiment"] == "resolution":
            setting += (("target", row["size"] // 100),)
        key = (row["experiment"], row["tessellation"], setting, row["operator"])
        groups.setdefault(key, []).append(row)
    out = []
    for (experiment, tessellation, setting, operator), members in groups.items():
        entry = {"experiment": experiment, "tessellation": tessellation, "operator": operator,
                 **{k: v for k, v in setting if k != "target"},
                 "vertices": float(np.mean([m["size"] for m in members])),
                 "rows": len(members),
                 "error": float(np.mean([m["error"] for m in members]))}
        if "error_raw" in members[0]:
            entry["error_raw"] = float(np.mean([m["error_raw"] for m in members]))
        out.append(entry)
    return out


def _valence_summary(valence_rows):
    """Error per valence, averaged over meshes and functions (valences seen >= 20 times)."""
    table = {}
    for row in valence_rows:
        table.setdefault((row["operator"], row["valence"]), []).append(row)
    out = []
    for (operator, k), members in sorted(table.items()):
        if sum(m["vertices"] for m in members) >= 20:
            out.append({"experiment": "valence", "tessellation": "irregular",
                        "operator": operator, "valence": k,
                        "vertices": sum(m["vertices"] for m in members), "rows": len(members),
                        "error": float(np.mean([m["error"] for m in members]))})
    return out


def reductions(summary):
    """Per grid resolution: 1 - error(weighted) / error(Laplace-Beltrami)."""
    grid = {(s["resolution"], s["operator"]): s["error"] for s in summary
            if s["experiment"] == "resolution" and s["tessellation"] == "grid"}
    return {r: 1 - grid[(r, "weighted")] / grid[(r, "laplace_beltrami")]
            for r in sorted({r for r, _ in grid})}


def _panel(ax, summary, experiment, tessellation, x_key, title, xlabel, log_x=True,
           group=None):
    """Error vs `x_key`, one line per operator (and per value of `group`, by style)."""
    chosen = [s for s in summary if s["experiment"] == experiment
              and s["tessellation"] == tessellation]
    groups = sorted({s.get(group) for s in chosen}, key=lambda g: (g is None, g))
    for operator in OPERATORS:
        for number, value in enumerate(groups):
            line = sorted((s[x_key], s["error"]) for s in chosen
                          if s["operator"] == operator and s.get(group) == value)
            if not line:
                continue
            xs, ys = zip(*line, strict=True)
            label = REGISTRY[operator].label + (f", {group.replace('_', ' ')} "
                                                f"{value}" if group else "")
            ax.plot(xs, ys, ["o-", "s--", "^:"][number % 3], color=REGISTRY[operator].colour,
                    label=label, markersize=4)
    if log_x:
        ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_title(title, fontsize=10)
    ax.set_xlabel(xlabel)
    ax.set_ylabel("normalized RMS error")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)


def figures(summary, out_dir):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(11, 8.5), dpi=100, layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(2, 2)
    _panel(axes[0, 0], summary, "resolution", "grid", "vertices",
           "(a) Kuhn grids", "vertices")
    _panel(axes[0, 1], summary, "resolution", "irregular", "vertices",
           f"(b) irregular meshes, {SMOOTHING} smoothing rounds", "vertices (mean)")
    _panel(axes[1, 0], summary, "resolution", "diamond", "vertices",
           f"(c) diamond meshes, {SMOOTHING} smoothing rounds (eps from 4 % to 0.1 %)",
           "vertices (mean over functions)", group="grid_side")
    _panel(axes[1, 1], summary, "valence", "irregular", "valence",
           "(d) irregular meshes, raw estimates, by valence", "incident tetrahedra",
           log_x=False)
    fig.suptitle("Mean-curvature error on the six analytic functions (Fig. 2)")
    fig2 = save_figure(fig, out_dir / "fig2.png")

    fig = Figure(figsize=(11, 4.2), dpi=100, layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(1, 2)
    _panel(axes[0], summary, "value_noise", "grid", "noise_percent",
           "(a) Gaussian noise in the value", "sigma, % of the field range", log_x=False)
    _panel(axes[1], summary, "normal_noise", "grid", "noise_percent",
           "(b) Gaussian noise along vertex normals", "sigma, % of the mean edge length",
           log_x=False)
    resolution = next(s["resolution"] for s in summary if s["experiment"] == "value_noise")
    fig.suptitle(f"Error under noise on the {resolution}^3 Kuhn grid (Fig. 3)")
    fig3 = save_figure(fig, out_dir / "fig3.png")
    return fig2, fig3


def run(out_dir, config: Config = Config(), *, cubic_sign=-1.0, say=lambda m: None):
    from volseg.analytic import functions as make_functions

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    functions = make_functions(cubic_sign)
    start = time.perf_counter()
    rows = grid_errors(functions, config.grid_resolutions, say)
    irregular, valence_rows = irregular_errors(functions, config.irregular_vertices,
                                               config.irregular_seeds, say)
    rows += irregular
    rows += diamond_errors(functions, config.diamond_sides, config.diamond_eps, say)
    rows += noise_errors(functions, config.noise_resolution, config.value_noise,
                         config.normal_noise, config.noise_seeds, say)
    summary = summarize(rows) + _valence_summary(valence_rows)
    paths = [write_csv(out_dir / "errors.csv", rows + valence_rows),
             write_csv(out_dir / "summary.csv", summary)]
    paths += figures(summary, out_dir)
    lines = ["Weighted distortion vs Laplace-Beltrami on Kuhn grids "
             "(1 - E_weighted / E_LB, E = error averaged over the six functions):"]
    found = reductions(summary)
    for resolution, value in found.items():
        lines.append(f"  {resolution}^3: {100 * value:+.1f} %")
    lines.append(f"  mean over resolutions: {100 * np.mean(list(found.values())):+.1f} % "
                 "(the paper: 29 % on average)")
    lines.append(f"total time {time.perf_counter() - start:.1f} s")
    text = "\n".join(lines) + "\n"
    paths.append(write_text(out_dir / "reduction.txt", text))
    say(text.strip())
    return paths, summary


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m pipelines.analytic",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", required=True, help="output folder")
    parser.add_argument("--quick", action="store_true",
                        help="small sizes (under a minute): grids to 33^3, meshes to ~2k vertices")
    parser.add_argument("--cubic-sign", type=float, default=-1.0, choices=[-1.0, 1.0],
                        help="sign of the cubic's x z^2 term (lost in the paper's text)")
    parser.add_argument("-q", "--quiet", action="store_true")
    args = parser.parse_args(argv)

    def say(message):
        if not args.quiet:
            print(f"analytic: {message}", file=sys.stderr, flush=True)

    try:
        paths, _ = run(args.out, QUICK if args.quick else Config(), cubic_sign=args.cubic_sign,
                       say=say)
    except OSError as err:
        print(f"analytic: error: {args.out}: {err.strerror}", file=sys.stderr)
        return 2
    for path in paths:
        print(path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
