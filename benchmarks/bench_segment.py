"""End to end: `volseg segment fuel` wall time (warm, interpreter start included)
paired with ``python -c "import numpy"`` in the same rounds (issue 56: at most 8x it),
`import volseg`, and a 256^3 volume through segment_volume.

    VOLSEG_DATA_DIR=../shared/data/volvis python benchmarks/bench_segment.py [--rounds 5]

The children run as a user's install does: with Python's bytecode cache written and
read. A shell that sets PYTHONDONTWRITEBYTECODE (some CI images and sandboxes do)
would compile every volseg module from source in every run, about 75 ms of a warm
fuel run here; it is unset for them. Rounds alternate the commands, so a busy machine
slows both sides of the ratio.
"""

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time

#: The children's environment: bytecode cached as on a user's machine (see above).
ENV = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}


def wall(argv):
    start = time.perf_counter()
    subprocess.run(argv, check=True, capture_output=True, env=ENV)
    return time.perf_counter() - start


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args()
    numpy = [sys.executable, "-c", "import numpy"]
    with tempfile.TemporaryDirectory() as out:
        cli = [sys.executable, "-m", "volseg", "segment", "fuel", "-o", out, "-q", "--force"]
        wall(cli)  # compile and cache kernels and bytecode
        wall(numpy)
        runs, bases = [], []
        for _ in range(args.rounds):
            runs.append(wall(cli))
            bases.append(wall(numpy))
        ratios = sorted(r / b for r, b in zip(runs, bases, strict=True))
        print(f"volseg segment fuel (64^3), warm: best {min(runs):.2f} s of {len(runs)}; "
              f"python -c 'import numpy': best {min(bases):.3f} s; ratio per round "
              f"{', '.join(f'{r:.1f}' for r in ratios)} (median {ratios[len(ratios) // 2]:.1f}x)")
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
                        "-q"], check=True, env=ENV)
        t = time.perf_counter() - start
        peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024**2
    print(f"volseg segment 256^3 uint8 .npy, end to end: {t:.1f} s, peak {peak:.2f} GB")


if __name__ == "__main__":
    main()
