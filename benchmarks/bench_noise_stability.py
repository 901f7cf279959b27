"""The full noise-stability run (3 datasets x 3 operators x 8 levels x 5 seeds = 360
tasks) on a LocalCluster of 2 workers, then of 1 worker, side by side: wall time of
each and the speedup. Each run starts from an empty output folder.

    VOLSEG_DATA_DIR=../shared/data/volvis python benchmarks/bench_noise_stability.py [--quick]

--quick: fuel only, 3 levels, 2 seeds (18 tasks), to check the script itself.
"""

import subprocess
import sys
import tempfile
import time


def timed_run(out, workers, extra):
    start = time.perf_counter()
    subprocess.run([sys.executable, "-m", "pipelines.noise_stability", "--out", out,
                    "--workers", str(workers), "-q", *extra], check=True)
    return time.perf_counter() - start


def main():
    extra = []
    if "--quick" in sys.argv:
        extra = ["--datasets", "fuel", "--levels", "0", "1", "5", "--seeds", "2"]
    times = {}
    for workers in (2, 1):
        with tempfile.TemporaryDirectory() as out:
            times[workers] = timed_run(out, workers, extra)
        print(f"{workers} worker(s): {times[workers]:.1f} s wall (cluster start included)")
    print(f"speedup of 2 workers over 1: {times[1] / times[2]:.2f}x")


if __name__ == "__main__":
    main()
