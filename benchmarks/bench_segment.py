"""End to end: `volseg segment fuel` wall time (warm, interpreter start included),
`import volseg`, and a 256^3 volume through segment_volume.

    VOLSEG_DATA_DIR=../shared/data/volvis python benchmarks/bench_segment.py
"""

import resource
import subprocess
import sys
import tempfile
import time


def wall(argv):
    start = time.perf_counter()
    subprocess.run(argv, check=True, capture_output=True)
    return time.perf_counter() - start


def main():
    with tempfile.TemporaryDirectory() as out:
        cli = [sys.executable, "-m", "volseg", "segment", "fuel", "-o", out, "-q", "--force"]
        wall(cli)  # compile and cache kernels
        runs = [wall(cli) for _ in range(3)]
        print(f"volseg segment fuel (64^3), warm: best {min(runs):.2f} s of {len(runs)}")
    imports = [wall([sys.executable, "-c", "import volseg"]) for _ in range(3)]
    print(f"import volseg (with interpreter start): {min(imports):.2f} s")
    with tempfile.TemporaryDirectory() as out:
        # A smooth random 256^3 uint8 volume, segmented end to end through the CLI
        # (read, curvature, Morse, NIfTI + PNG outputs); peak memory of that child.
        import numpy as np
        from scipy.ndimage import gaussian_filter

        rng = np.random.default_rng(0)
        v = gaussian_filter((255 * rng.random((256, 256, 256), dtype=np.float32)), 1.5)
        v = (255 * (v - v.min()) / np.ptp(v)).astype(np.uint8)
        np.save(f"{out}/big.npy", v)
        del v
        start = time.perf_counter()
        subprocess.run([sys.executable, "-m", "volseg", "segment", f"{out}/big.npy", "-o", out,
                        "-q"], check=True)
        t = time.perf_counter() - start
        peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024**2
    print(f"volseg segment 256^3 uint8 .npy, end to end: {t:.1f} s, peak {peak:.2f} GB")


if __name__ == "__main__":
    main()
