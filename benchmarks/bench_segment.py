"""End to end: `volseg segment fuel` wall time (warm, interpreter start included),
`import volseg`, and a 256^3 volume through segment_volume.

    VOLSEG_DATA_DIR=../shared/data/volvis python benchmarks/bench_segment.py
"""

import subprocess
import sys
import tempfile
import time

from _common import in_fresh_process


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
    r = in_fresh_process("""
import json, resource, time
import numpy as np
from scipy.ndimage import gaussian_filter
from volseg import segment_volume
v = (255 * np.random.default_rng(0).random((256, 256, 256), dtype=np.float32)).astype(np.uint8)
v = gaussian_filter(v, 1.5)
segment_volume(v[:16, :16, :16], n_regions=2)
start = time.perf_counter(); s = segment_volume(v); t = time.perf_counter() - start
print(json.dumps(dict(t=t, peak=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024**2)))
""")
    print(f"segment_volume 256^3 uint8: {r['t']:.1f} s, peak {r['peak']:.2f} GB")


if __name__ == "__main__":
    main()
