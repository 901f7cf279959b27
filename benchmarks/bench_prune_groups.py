"""The hypervolume pruning decided in groups against the sequential one, side by side
(issue 30).

    python benchmarks/bench_prune_groups.py --sizes 256 512 [--edges 64 128] [--repeat 2]

For each size N: the synthetic uint8 field of `bench_blockwise.py` (N^3), the hierarchy
`volseg segment` builds of it in memory (not timed), the cells' hypervolumes in fixed point,
then, interleaved --repeat times: the sequential pruning (`_prune.prune` on the int64
keys) and the grouped one (`_prune_groups.grouped_prune`, leaves of edge^3 voxels),
their wall times and whether order and extinctions are equal (they must be: the script
fails otherwise). It also prints, for each depth of the groups' tree, the edges the
groups there receive, the share of all events they decide and the frozen regions they
pass up: what a distributed pruning would send between levels.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from bench_blockwise import smooth_block  # noqa: E402


def hierarchy_of(n: int):
    """The hierarchy `volseg segment` builds of the field (its default cut made)."""
    from volseg.segment import SegmentRequest, run_stages

    field = smooth_block({None: {"array-location": [(0, n)] * 3}}, n)
    result, _ = run_stages(field, SegmentRequest.checked())
    return result.hierarchy


def levels(source, target, base, leaf_of, tree) -> dict:
    """{depth: [edges received, decided, frozen regions passed up]} of `tree`."""
    from volseg.morse._prune_groups import GroupState, leaves

    grid = tuple(tree[-1][1])
    leaf_states = dict(enumerate(leaves(source, target, base, leaf_of, int(np.prod(grid)))))
    depth = {len(tree) - 1: 0}
    for i in range(len(tree) - 1, -1, -1):
        for child in tree[i][3:]:
            if child is not None:
                depth[child] = depth[i] + 1
    passed, out = {}, {}
    for i, (lo, _, _, low, high) in enumerate(tree):
        state = (leaf_states.pop(int(np.ravel_multi_index(lo, grid))) if low is None
                 else GroupState.joined([passed.pop(low), passed.pop(high)]))
        row = out.setdefault(depth[i], [0, 0, 0])
        row[0] += len(state.event)
        found, passed[i] = state.pruned()
        row[1] += len(found[0])
        row[2] += len(passed[i].rid)
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--sizes", nargs="+", type=int, default=[256])
    p.add_argument("--edges", nargs="+", type=int, default=[64])
    p.add_argument("--repeat", type=int, default=2)
    args = p.parse_args(argv)
    from volseg.morse import _prune
    from volseg.morse._prune_groups import grid_leaves, grouped_prune

    for n in args.sizes:
        h = hierarchy_of(n)
        base = h._cell_base("hypervolume").sums
        n_ev = len(h.source)
        print(f"{n}^3: {len(h.maxima)} maxima, {n_ev} events", flush=True)
        times = {}
        for _ in range(args.repeat):
            start = time.perf_counter()
            want = np.empty(n_ev, np.int64), np.empty(n_ev, np.int64)
            _prune.prune(h.source, h.target, len(h.maxima), base, *want)
            times.setdefault("sequential", []).append(time.perf_counter() - start)
            for edge in args.edges:
                start = time.perf_counter()
                leaf_of, tree = grid_leaves(h.maxima, h.shape, edge)
                got = grouped_prune(h.source, h.target, base, leaf_of, tree)
                times.setdefault(f"grouped {edge}^3", []).append(time.perf_counter() - start)
                if not all(np.array_equal(a, b) for a, b in zip(got, want, strict=True)):
                    raise SystemExit(f"{n}^3, leaves {edge}^3: the grouped pruning differs")
        for name, t in times.items():
            print(f"  {name}: fastest {min(t):.2f} s (every run: "
                  f"{', '.join(f'{x:.2f}' for x in t)}); same order and extinctions", flush=True)
        for edge in args.edges:
            leaf_of, tree = grid_leaves(h.maxima, h.shape, edge)
            print(f"  leaves {edge}^3, by depth (0 = root): edges received / decided "
                  "(share of all events) / frozen regions passed up")
            for d, (got, decided, up) in sorted(levels(h.source, h.target, base, leaf_of,
                                                       tree).items(), reverse=True):
                print(f"    depth {d}: {got} / {decided} ({decided / max(n_ev, 1):.1%}) / {up}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
