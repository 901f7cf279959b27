"""Masked against unmasked segmentation, side by side in one run (issue 13).

    python benchmarks/bench_mask.py          # fuel, and a 256^3 volume that is 60 % empty

A mask takes voxels out of the Morse graph (fewer vertices to walk), so a masked run
should cost no more than the unmasked one. Each measurement runs in a fresh
interpreter; times are the best of 3 in that interpreter, after one warm-up run.
"""

from _common import in_fresh_process

CODE = """
import json, time
import numpy as np
from scipy.ndimage import gaussian_filter
from volseg import read_volume, segment_volume
if "{source}" == "fuel":
    data = read_volume("{fuel}").data
else:
    n = {n}
    f = gaussian_filter(np.random.default_rng(0).standard_normal((n, n, n)), 3)
    data = np.round(255 * (f - f.min()) / np.ptp(f)).astype(np.uint8)
    data[: 3 * n // 5] = 0  # an exactly empty 60 %, like a scanner's background (auto masks > 50 %)
segment_volume(np.random.default_rng(1).random((16, 16, 16)), mask="{mask}")  # warm kernels
best, stages = float("inf"), None
for _ in range(3):
    start = time.perf_counter()
    result = segment_volume(data, mask="{mask}")
    elapsed = time.perf_counter() - start
    if elapsed < best:
        best, stages = elapsed, result.timings
print(json.dumps(dict(t=best, stages=stages, regions=result.n_regions,
                      maxima=len(result.hierarchy.maxima), voxels=result.mask.voxels)))
"""


def main():
    import os
    from pathlib import Path

    fuel = Path(os.environ.get("VOLSEG_DATA_DIR", Path(__file__).resolve().parents[2]
                               / "shared" / "data" / "volvis")) / "fuel_64x64x64_uint8.raw"
    for source, n in [("fuel", 64), ("60%-empty", 256)]:
        runs = {mask: in_fresh_process(CODE.format(source=source, n=n, mask=mask, fuel=fuel))
                for mask in ("none", "auto")}
        for mask, r in runs.items():
            stages = ", ".join(f"{k} {v:.3f} s" for k, v in r["stages"].items())
            print(f"{source} {n}^3 mask {mask:4s}: {r['t']:.3f} s ({stages}); {r['voxels']} voxels "
                  f"in the Morse graph, {r['maxima']} maxima, {r['regions']} regions", flush=True)
        print(f"{source}: masked / unmasked time = {runs['auto']['t'] / runs['none']['t']:.2f}",
              flush=True)


if __name__ == "__main__":
    main()
