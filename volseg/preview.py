"""A PNG montage that shows at a glance what a segmentation found."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def write_preview(path, volume, curvature, labels, *, title="") -> Path:
    """Mid slices along x, y, z: the volume, its curvature, the labels over the volume.

    Written to `path` as PNG (the caller handles atomic renaming).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import ListedColormap

    volume = np.asarray(volume, dtype=float)
    k = int(labels.max()) + 1
    palette = plt.get_cmap("tab20")(np.arange(max(k, 1)) % 20)
    cmap = ListedColormap(palette)
    lim = np.percentile(np.abs(curvature), 99) or 1.0
    fig, axes = plt.subplots(3, 3, figsize=(10.5, 10), constrained_layout=True)
    for row, axis in enumerate("xyz"):
        index = [slice(None)] * 3
        index[row] = volume.shape[row] // 2
        index = tuple(index)
        vol, cur, lab = volume[index].T, curvature[index].T, labels[index].T
        a = axes[row, 0].imshow(vol, origin="lower", cmap="gray")
        b = axes[row, 1].imshow(cur, origin="lower", cmap="RdBu_r", vmin=-lim, vmax=lim)
        axes[row, 2].imshow(vol, origin="lower", cmap="gray")
        axes[row, 2].imshow(lab, origin="lower", cmap=cmap, vmin=-0.5, vmax=k - 0.5, alpha=0.55,
                            interpolation="nearest")
        other = [c for c in "xyz" if c != axis]
        for col, name in enumerate(["volume", "curvature", "regions"]):
            axes[row, col].set_title(f"{name}, {axis} = {index[row]}", fontsize=9)
            axes[row, col].set_xlabel(other[0], fontsize=8)
            axes[row, col].set_ylabel(other[1], fontsize=8)
            axes[row, col].tick_params(labelsize=7)
        if row == 0:
            fig.colorbar(a, ax=axes[:, 0], shrink=0.4, location="bottom", label="value")
            fig.colorbar(b, ax=axes[:, 1], shrink=0.4, location="bottom",
                         label="mean curvature (+ peak, - valley)")
            handles = [plt.Rectangle((0, 0), 1, 1, color=palette[i]) for i in range(min(k, 10))]
            axes[0, 2].legend(handles, [f"region {i}" for i in range(min(k, 10))],
                              fontsize=6, loc="upper right", framealpha=0.7,
                              title=f"{k} regions" + (" (first 10)" if k > 10 else ""),
                              title_fontsize=7)
    fig.suptitle(title, fontsize=11)
    fig.savefig(path, dpi=80, format="png")
    plt.close(fig)
    return Path(path)
