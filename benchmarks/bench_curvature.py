"""Curvature speed and memory: explicit mesh (vertex_curvature) and Kuhn stencil (grid_curvature).

    python benchmarks/bench_curvature.py

Each measurement runs in a fresh interpreter, so peak memory is its own. Prints the
time per size (linear scaling shows as a constant time per voxel) and the stencil's
speedup over the explicit mesh at 64^3.
"""

from _common import in_fresh_process

MESH = """
import json, resource, time
import numpy as np
from scipy.ndimage import gaussian_filter
from volseg import tessellation, vertex_curvature
f = gaussian_filter(np.random.default_rng(0).standard_normal(({n},) * 3), 2)
v, s = tessellation.kuhn_grid_mesh(f)
vertex_curvature(v[:1000], s[(s < 1000).all(1)][:50], "{op}", boundary="partial")  # warm kernels
start = time.perf_counter(); vertex_curvature(v, s, "{op}"); t = time.perf_counter() - start
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
print(json.dumps(dict(t=t, simplices=len(s), peak_mb=peak)))
"""

GRID = """
import json, resource, time
import numpy as np
from volseg.curvature import grid_curvature
f = np.random.default_rng(0).random(({n},) * 3, dtype=np.float32)
grid_curvature(f[:8, :8, :8], "{op}")  # warm kernels
base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
start = time.perf_counter(); grid_curvature(f, "{op}"); t = time.perf_counter() - start
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
print(json.dumps(dict(t=t, peak_mb=peak, base_mb=base)))
"""


def main():
    mesh_64 = {}
    for op in ["weighted", "laplace_beltrami"]:
        for n in [32, 64, 96]:
            r = in_fresh_process(MESH.format(n=n, op=op))
            if n == 64:
                mesh_64[op] = r["t"]
            print(f"vertex_curvature {op:16s} {n}^3 Kuhn mesh ({r['simplices']} tets): "
                  f"{r['t']:.2f} s, "
                  f"{1e9 * r['t'] / r['simplices']:.0f} ns/tet, peak {r['peak_mb']:.0f} "
                  "MB", flush=True)
    for op in ["weighted", "laplace_beltrami", "unweighted", "intrinsic"]:
        for n in [64, 128, 192, 256]:
            r = in_fresh_process(GRID.format(n=n, op=op))
            line = (f"grid_curvature   {op:16s} {n}^3: {r['t']:.2f} s, {1e9 * r['t'] / n**3:.0f} "
                    "ns/voxel, "
                    f"peak {r['peak_mb']:.0f} MB")
            if n == 64 and op in mesh_64:
                line += f", {mesh_64[op] / r['t']:.0f}x faster than the explicit mesh"
            print(line, flush=True)


if __name__ == "__main__":
    main()
