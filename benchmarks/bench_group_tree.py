"""What each level of the tree of block groups holds and passes up (issue 30).

    python benchmarks/bench_group_tree.py --sizes 256 512 [--chunks 128]

On the synthetic uint8 field of `bench_blockwise.py` (its curvature, blockwise, as
`volseg segment` computes it), the Morse build runs in this process with Dask's
threads, and every group of the tree reports:

- the union-find (`_group_tree`): the items it sweeps (edges and elder queries), the
  events it decides, the items it passes up, and their bytes;
- the exits (`_exits`): the voxels of its face map, the exits it cannot resolve.

Printed per tree level (0 = the blocks, the last = the root): the groups, the sums
and the largest group. The root's share is what no tree can spread: it scales with
the volume's middle cross-section, not with the volume (the scaling argument of the
README's "how far this design goes").
"""

from __future__ import annotations

import argparse
import sys
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))


def level_of(groups):
    """Each group's height in the tree (0 for a block)."""
    level = []
    for _, _, axis, low, high in groups:
        level.append(0 if axis is None else 1 + max(level[low], level[high]))
    return level


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[256, 512])
    parser.add_argument("--chunks", type=int, default=128)
    parser.add_argument("--folder", default="/tmp/volseg-bench-blockwise")
    args = parser.parse_args(argv)

    import dask
    import dask.array as da
    from bench_blockwise import write_inputs

    from volseg import descending_complex, grid_curvature
    from volseg.io import read_zarr
    from volseg.morse import _group_tree
    from volseg.morse.blocks import _exits

    records = defaultdict(list)
    decide = _group_tree.decide

    def recorded_decide(items, faces, group_id):
        decided, group = decide(items, faces, group_id)
        records["tree"].append((group_id, len(items.a), len(decided[0]), len(group.items.a),
                                group.items.nbytes))
        return decided, group

    up = _exits._up

    def recorded_up(keys, ends, box, shape):
        out = up(keys, ends, box, shape)
        records["exits"].append((tuple(box[0]), tuple(box[1]), len(keys), len(out[0][0]),
                                 len(out[1])))
        return out

    _group_tree.decide = recorded_decide
    _exits._up = recorded_up
    folder = Path(args.folder)
    folder.mkdir(parents=True, exist_ok=True)
    for n in args.sizes:
        records.clear()
        zarr_path, _ = write_inputs(folder, n, args.chunks, False)
        field = read_zarr(zarr_path).data
        start = time.perf_counter()
        with dask.config.set(scheduler="threads"):
            curvature = grid_curvature(da.asarray(field)).persist()
            hierarchy = descending_complex(curvature)
        seconds = time.perf_counter() - start
        grid = tuple(len(c) for c in curvature.chunks)
        groups = _group_tree.block_tree(grid)
        level = level_of(groups)
        print(f"\n{n}^3, {args.chunks}^3 blocks ({np.prod(grid)}), {len(hierarchy.maxima)} maxima, "
              f"{len(hierarchy.young)} events, {seconds:.0f} s")
        by_level = defaultdict(list)
        for group_id, swept, decided, passed, nbytes in records["tree"]:
            by_level[level[group_id]].append((swept, decided, passed, nbytes))
        print("| level | groups | items swept (largest) | events decided (share) "
              "| items up (largest, MB) |")
        print("| --- | --- | --- | --- | --- |")
        total = len(hierarchy.young)
        for lv in sorted(by_level):
            rows = np.array(by_level[lv])
            print(f"| {lv} | {len(rows)} | {rows[:, 0].sum()} ({rows[:, 0].max()}) "
                  f"| {rows[:, 1].sum()} ({rows[:, 1].sum() / total:.1%}) "
                  f"| {rows[:, 2].sum()} ({rows[:, 2].max()}, {rows[:, 3].max() / 1e6:.1f}) |")
        boxes = {(g[0], g[1]): level[i] for i, g in enumerate(groups)}
        exits_by_level = defaultdict(list)
        for lo, hi, keys, face, refs in records["exits"]:
            blocks = tuple(int(np.searchsorted(np.cumsum((0,) + c), v))
                           for c, v in zip(curvature.chunks, lo, strict=True))
            blocks_hi = tuple(int(np.searchsorted(np.cumsum((0,) + c), v))
                              for c, v in zip(curvature.chunks, hi, strict=True))
            exits_by_level[boxes[(blocks, blocks_hi)]].append((keys, face, refs))
        print("| level | exits: map voxels (largest) | face map up (largest) | unresolved |")
        print("| --- | --- | --- | --- |")
        for lv in sorted(exits_by_level):
            rows = np.array(exits_by_level[lv])
            print(f"| {lv} | {rows[:, 0].sum()} ({rows[:, 0].max()}) "
                  f"| {rows[:, 1].sum()} ({rows[:, 1].max()}) | {rows[:, 2].sum()} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
