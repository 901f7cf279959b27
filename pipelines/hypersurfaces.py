"""The paper's evaluation carried to hypersurfaces that are not graphs (issue 15).

    python -m pipelines.hypersurfaces --out runs/hypersurfaces [--quick]

Part 1, isosurfaces in R^4: four implicit hypersurfaces with exact mean curvature
(`volseg.analytic.HYPERSURFACES`: the round 3-sphere, an ellipsoid, S^1 x S^2 and a
moving, growing blob in space-time) are extracted from their samples on [-1, 1]^4
(`volseg.tessellation.isosurface`) at increasing resolution, with and without the
mesh-quality option (`relax_isosurface`, 10 rounds), and both operators are
compared with the exact H at every vertex with a complete star, raw and after 50
rounds of 1-ring averaging (the paper's smoothing).

Part 2, how much is the mesh and how much the operator: the six graph test functions
of docs/design.md section 7 on four meshes of the cube with about the same vertex count:
the Kuhn grid, random Delaunay (dart throwing), the same after optimal-Delaunay
(ODT) smoothing, and a jittered body-centred-cubic lattice.

Errors. Part 1: relative RMS, ``RMS(estimate - H) / mean |H|`` (the range of H,
the paper's normaliser, is 0 on the sphere), and the median of ``estimate / H - 1``.
Part 2: the paper's normalized RMS (range of the exact values), averaged over the
six functions. Writes ``hypersurfaces.csv``, ``cube_meshes.csv``,
``hypersurfaces.png`` and ``summary.txt`` atomically.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from volseg import mesh, vertex_curvature
from volseg.analytic import FUNCTIONS, HYPERSURFACES, normalized_rms_error
from volseg.tessellation import isosurface, quality, relax_isosurface

from ._output import save_figure, write_csv, write_text

OPERATORS = ("weighted", "laplace_beltrami")
SMOOTHING = 50
RELAX = 10


def relative_errors(estimate, exact) -> dict:
    known = np.isfinite(estimate)
    e, h = estimate[known], exact[known]
    return {"relative_rms": float(np.sqrt(np.mean((e - h) ** 2)) / np.mean(np.abs(h))),
            "median_ratio_minus_1": float(np.median(e / h) - 1),
            "vertices_measured": int(known.sum())}


def hypersurface_rows(resolutions, say) -> list[dict]:
    rows = []
    for case in HYPERSURFACES.values():
        for resolution in resolutions:
            field, h = case.sample(resolution)
            start = time.perf_counter()
            raw = isosurface(field, case.level, spacing=h, origin=(-1.0,) * 4)
            meshes = {"marching": raw}
            extracted = time.perf_counter() - start
            start = time.perf_counter()
            meshes["relaxed"] = relax_isosurface(raw, field, case.level, spacing=h,
                                                 origin=(-1.0,) * 4, iterations=RELAX)
            relaxed_in = time.perf_counter() - start
            for kind, surface in meshes.items():
                exact = case.mean_curvature(surface.vertices)
                grade = quality(surface.vertices, surface.simplices)
                for operator in OPERATORS:
                    estimate = vertex_curvature(surface.vertices, surface.simplices, operator,
                                                boundary="nan")
                    smoothed = mesh.ring_average(estimate, surface.simplices, SMOOTHING)
                    for setting, values in (("raw", estimate), ("smoothed", smoothed)):
                        rows.append({"surface": case.name, "resolution": resolution,
                                     "mesh": kind, "operator": operator, "setting": setting,
                                     **relative_errors(values, exact),
                                     "vertices": len(surface.vertices),
                                     "tetrahedra": len(surface.simplices),
                                     "min_dihedral": grade["min"], "p1_dihedral": grade["p1"],
                                     "seconds_extract": extracted,
                                     "seconds_relax": relaxed_in if kind == "relaxed" else 0.0})
            best = [r for r in rows[-8:] if r["setting"] == "raw"]
            say(f"{case.name} {resolution}^4: " + ", ".join(
                f"{r['mesh']}/{r['operator']} {r['relative_rms']:.3f}" for r in best))
    return rows


# ---------------------------------------------------------------- part 2: cube meshes


def jittered_bcc(m: int, jitter: float, rng) -> tuple:
    """Body-centred-cubic points on [-1, 1]^3 (m^3 corners + (m-1)^3 centres), interior
    points moved by up to `jitter` of the spacing; Delaunay tetrahedra."""
    from scipy.spatial import Delaunay

    axis = np.linspace(-1, 1, m)
    h = axis[1] - axis[0]
    corners = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), -1).reshape(-1, 3)
    centres = (np.stack(np.meshgrid(*[axis[:-1] + h / 2] * 3, indexing="ij"), -1).reshape(-1, 3))
    points = np.vstack([corners, centres])
    inside = (np.abs(points) < 1 - 1e-9).all(axis=1)
    points[inside] += rng.uniform(-jitter * h, jitter * h, (int(inside.sum()), 3))
    return points, Delaunay(points).simplices.astype(np.intp), ~inside


def odt_smooth(points, fixed, iterations: int = 10) -> tuple:
    """Optimal Delaunay triangulation smoothing (Alliez et al. 2005): each free vertex
    moves to the volume-weighted mean of the circumcentres of its tetrahedra, then
    the points are re-triangulated."""
    from scipy.spatial import Delaunay

    points = points.copy()
    for _ in range(iterations):
        tets = Delaunay(points).simplices
        p = points[tets]
        edges = p[:, 1:] - p[:, :1]
        volume = np.abs(np.linalg.det(edges)) / 6
        rhs = 0.5 * np.einsum("tij,tij->ti", edges, edges)
        keep = volume > 1e-12 * np.median(volume)
        centre = p[keep, 0] + np.linalg.solve(edges[keep], rhs[keep][..., None])[..., 0]
        # A circumcentre outside the cube (flat tetrahedra at the boundary) would drag
        # vertices onto it; those tetrahedra vote with their centroid instead.
        outside = (np.abs(centre) > 1).any(axis=1)
        centre[outside] = p[keep][outside].mean(axis=1)
        weight = np.repeat(volume[keep], 4)
        total = np.bincount(tets[keep].ravel(), weight, minlength=len(points))
        moved = np.stack([np.bincount(tets[keep].ravel(), weight * np.repeat(centre[:, a], 4),
                                      minlength=len(points)) for a in range(3)], -1)
        free = ~fixed & (total > 0)
        target = moved[free] / total[free, None]
        points[free] = np.clip(target, -1 + 1e-6, 1 - 1e-6)
    return points, Delaunay(points).simplices.astype(np.intp)


def cube_meshes(m: int, seed: int) -> dict:

    from volseg.tessellation import irregular_cube_mesh, kuhn_cube_mesh
    from volseg.tessellation.irregular import delaunay_tetrahedra, orient_upward

    rng = np.random.default_rng(seed)
    out = {}
    vertices, tets = kuhn_cube_mesh(m)
    out["kuhn_grid"] = (vertices[:, :3], tets, np.zeros(len(vertices), bool))
    random = irregular_cube_mesh(m ** 3, seed=seed, smoothing_iterations=0)
    out["random_delaunay"] = (random.points, random.tetrahedra, random.boundary)
    points, _ = odt_smooth(random.points, random.boundary)
    out["odt_smoothed"] = (points, orient_upward(points, delaunay_tetrahedra(points)),
                           random.boundary)
    points, tets, boundary = jittered_bcc(int(round((m ** 3 / 2) ** (1 / 3))) + 1, 0.15, rng)
    out["jittered_bcc"] = (points, orient_upward(points, delaunay_tetrahedra(points)), boundary)
    return out


def cube_rows(m: int, seeds, say) -> list[dict]:
    from volseg.tessellation import lift

    rows = []
    for seed in seeds:
        for name, (points, tets, _) in cube_meshes(m, seed).items():
            grade = quality(np.c_[points, np.zeros(len(points))], tets)
            for operator in OPERATORS:
                raw, smooth = [], []
                for function in FUNCTIONS.values():
                    vertices = lift(points, function)
                    estimate = vertex_curvature(vertices, tets, operator, boundary="nan")
                    exact = function.mean_curvature(*points.T)
                    raw.append(normalized_rms_error(estimate, exact))
                    smooth.append(normalized_rms_error(
                        mesh.ring_average(estimate, tets, SMOOTHING), exact))
                rows.append({"mesh": name, "seed": seed, "operator": operator,
                             "vertices": len(points), "tetrahedra": len(tets),
                             "raw_error": float(np.mean(raw)),
                             "smoothed_error": float(np.mean(smooth)),
                             "min_dihedral": grade["min"], "p1_dihedral": grade["p1"],
                             "share_below_10_degrees": grade["below_10"]})
            pair = rows[-2:]
            say(f"cube {name} seed {seed}: raw {pair[0]['raw_error']:.4f} (weighted) "
                f"{pair[1]['raw_error']:.4f} (LB); min dihedral {grade['min']:.1f}")
    return rows


# ---------------------------------------------------------------- report


def figure(rows, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(HYPERSURFACES)
    fig, axes = plt.subplots(2, len(names), figsize=(4.2 * len(names), 7.5), sharex=True)
    styles = {("marching", "weighted"): ("C0", "--"),
              ("marching", "laplace_beltrami"): ("C1", "--"),
              ("relaxed", "weighted"): ("C0", "-"), ("relaxed", "laplace_beltrami"): ("C1", "-")}
    for row_index, setting in enumerate(("raw", "smoothed")):
        for column, name in enumerate(names):
            ax = axes[row_index, column]
            for (kind, operator), (colour, dash) in styles.items():
                chosen = sorted((r for r in rows if r["surface"] == name and r["mesh"] == kind
                                 and r["operator"] == operator and r["setting"] == setting),
                                key=lambda r: r["resolution"])
                ax.plot([r["resolution"] for r in chosen], [r["relative_rms"] for r in chosen],
                        dash, color=colour, marker="o", ms=3,
                        label=f"{operator.replace('_', '-')}, {kind}")
            ax.set_yscale("log")
            ax.set_title(f"{name} ({setting})", fontsize=10)
            ax.grid(alpha=0.3)
            if column == 0:
                ax.set_ylabel("RMS(estimate - H) / mean |H|")
            if row_index == 1:
                ax.set_xlabel("samples per axis")
    axes[0, 0].legend(fontsize=7)
    fig.suptitle("Mean curvature of isosurfaces in R^4: marching mesh (dashed) vs relaxed "
                 "(solid), weighted distortion (blue) vs Laplace-Beltrami (orange)", fontsize=10)
    fig.tight_layout()
    save_figure(fig, path)
    plt.close(fig)


def summary_text(rows, cube) -> str:
    lines = ["Isosurfaces in R^4, relative RMS error and median(estimate / H) - 1, raw estimates:"]
    top = max(r["resolution"] for r in rows)
    for name in HYPERSURFACES:
        for kind in ("marching", "relaxed"):
            for operator in OPERATORS:
                r = next(r for r in rows if r["surface"] == name and r["resolution"] == top
                         and r["mesh"] == kind and r["operator"] == operator
                         and r["setting"] == "raw")
                lines.append(f"  {name:12s} {top}^4 {kind:8s} {operator:16s} rms "
                             f"{r['relative_rms']:.4f}"
                             f"  median {r['median_ratio_minus_1']:+.4f}  min dihedral "
                             f"{r['min_dihedral']:.1f}")
    lines.append("\nCube meshes (paper's six functions, normalized RMS, mean over seeds):")
    for name in dict.fromkeys(r["mesh"] for r in cube):
        parts = []
        for operator in OPERATORS:
            chosen = [r for r in cube if r["mesh"] == name and r["operator"] == operator]
            parts.append(f"{operator} raw {np.mean([r['raw_error'] for r in chosen]):.4f} "
                         f"smoothed {np.mean([r['smoothed_error'] for r in chosen]):.4f}")
        lines.append(f"  {name:16s} " + "; ".join(parts))
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default="runs/hypersurfaces", help="output folder")
    parser.add_argument("--quick", action="store_true", help="small resolutions (about a minute)")
    args = parser.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    def say(message):
        print(f"hypersurfaces: {message}", file=sys.stderr, flush=True)

    resolutions = (9, 13, 17) if args.quick else (9, 13, 17, 25, 33)
    rows = hypersurface_rows(resolutions, say)
    write_csv(out / "hypersurfaces.csv", rows)
    cube = cube_rows(11 if args.quick else 17, (0,) if args.quick else (0, 1), say)
    write_csv(out / "cube_meshes.csv", cube)
    figure(rows, out / "hypersurfaces.png")
    text = summary_text(rows, cube)
    write_text(out / "summary.txt", text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
