"""The `volseg` command line: argparse only, every action is a library call.

Exit codes: 0 done, 2 bad input or usage (one line on stderr), 1 unexpected failure.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from ._version import __version__

OPERATOR_CHOICES = ["weighted", "unweighted", "laplace-beltrami", "intrinsic"]


class UsageError(ValueError):
    """Bad input or usage: exit code 2."""


def _get_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="volseg",
        description="Segment volumes by the mean curvature of their graph in R^4 and a "
        "persistence-simplified descending Morse complex.",
    )
    parser.add_argument("--version", action="version", version=f"volseg {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)

    seg = sub.add_parser("segment", help="segment volume files or named datasets")
    seg.add_argument("inputs", nargs="+", metavar="INPUT",
                     help="a volume file (.raw, .dat, .nrrd, .nii, .npy) or a dataset name")
    seg.add_argument("-o", "--out-dir", default=".", help="output folder (default: .)")
    seg.add_argument("--operator", choices=OPERATOR_CHOICES, default="weighted")
    cut = seg.add_mutually_exclusive_group()
    cut.add_argument("--regions", type=int, metavar="K", help="number of regions (default 30)")
    cut.add_argument("--min-persistence", type=float, metavar="T", help="persistence threshold")
    seg.add_argument("--shape", type=int, nargs=3, metavar=("X", "Y", "Z"))
    seg.add_argument("--dtype", help="voxel type of raw input (uint8, uint16, float32, ...)")
    seg.add_argument("--value-scale", type=float, metavar="S",
                     help="scale of the value axis (default: graph as tall as it is wide)")
    seg.add_argument("--noise", type=float, metavar="SIGMA_PERCENT",
                     help="add Gaussian noise, sigma in percent of the value range")
    seg.add_argument("--seed", type=int, default=0, help="seed of --noise (default 0)")
    seg.add_argument("--force", action="store_true", help="overwrite existing outputs")
    seg.add_argument("--json", action="store_true", help="print the summaries as JSON on stdout")
    seg.add_argument("-q", "--quiet", action="store_true", help="no progress on stderr")

    fetch = sub.add_parser("fetch", help="download and verify named datasets")
    fetch.add_argument("names", nargs="+", metavar="NAME")

    demo = sub.add_parser("demo", help="segment a built-in synthetic volume (offline)")
    demo.add_argument("-o", "--out-dir", default="volseg-demo")
    demo.add_argument("-q", "--quiet", action="store_true")

    info = sub.add_parser("info", help="describe a volume file or dataset")
    info.add_argument("input", metavar="INPUT")
    info.add_argument("--shape", type=int, nargs=3, metavar=("X", "Y", "Z"))
    info.add_argument("--dtype")

    compare = sub.add_parser("compare", help="compare two label volumes (Huang-Dom)")
    compare.add_argument("labels_a", metavar="LABELS_A")
    compare.add_argument("labels_b", metavar="LABELS_B")
    compare.add_argument("--json", action="store_true")
    return parser


def _progress(quiet):
    def say(message):
        if not quiet:
            print(f"volseg: {message}", file=sys.stderr, flush=True)
    return say


def _load(input_name, shape=None, dtype=None):
    """(Volume, path) of a volume file or a named dataset (`data_fetch.resolve`)."""
    import data_fetch

    from .io import read_volume

    path = data_fetch.resolve(input_name)
    return read_volume(path, shape=shape, dtype=dtype), path


def _check_out_dir(out_dir: Path):
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise UsageError(f"{out_dir}: cannot create the output folder ({err.strerror})") from None
    if not os.access(out_dir, os.W_OK):
        raise UsageError(f"{out_dir}: the output folder is not writable")


def _outputs(out_dir: Path, name: str) -> dict:
    return {kind: out_dir / f"{name}_{kind}{ext}" for kind, ext in
            [("labels", ".nii.gz"), ("curvature", ".nii.gz"), ("summary", ".json"),
             ("preview", ".png")]}


def segment_to_files(volume, out_dir, *, name, operator="weighted", n_regions=None,
                     min_persistence=None, value_scale=None, noise=None, seed=0, force=False,
                     source=None, say=lambda message: None) -> dict:
    """Segment `volume` and write labels, curvature, summary and preview into `out_dir`.

    All four files are written to temporary names first and renamed at the end, so a
    failure leaves no partial output. Returns the summary dictionary.
    """
    import data_fetch

    from .io import write_volume
    from .noise import add_value_noise
    from .preview import write_preview
    from .segment import segment_volume

    out_dir = Path(out_dir)
    targets = _outputs(out_dir, name)
    existing = [str(p) for p in targets.values() if p.exists()]
    if existing and not force:
        raise UsageError(f"{existing[0]} exists (and {len(existing) - 1} more outputs); "
                         "use --force to overwrite")
    started = time.perf_counter()
    data = np.asarray(volume)
    if noise:
        data = add_value_noise(data, noise, seed=seed)
    say(f"{name}: curvature ({operator}) and Morse complex of a {'x'.join(map(str, data.shape))} volume")
    result = segment_volume(data, operator=operator, n_regions=n_regions,
                            min_persistence=min_persistence, value_scale=value_scale,
                            spacing=getattr(volume, "spacing", None))
    labels = result.labels
    sizes = np.bincount(labels.ravel(), minlength=result.n_regions)
    regions = []
    for region, top in enumerate(result.region_maxima()):
        x, y, z = (int(c) for c in np.unravel_index(top, labels.shape))
        regions.append({"label": region, "size": int(sizes[region]), "maximum": [x, y, z],
                        "curvature_at_maximum": float(result.curvature[x, y, z])})
    summary = {
        "volseg_version": __version__,
        "input": str(source) if source else name,
        "input_sha256": data_fetch.sha256(source) if source else None,
        "shape": list(labels.shape),
        "spacing": list(result.spacing),
        "operator": result.operator,
        "value_scale": result.value_scale,
        "noise_percent": noise or 0.0,
        "seed": seed if noise else None,
        "n_regions": result.n_regions,
        "requested_regions": n_regions,
        "min_persistence": result.min_persistence,
        "n_maxima": int(len(result.hierarchy.maxima)),
        "regions": regions,
        "outputs": {kind: str(p) for kind, p in targets.items()},
        "timings_s": {k: round(v, 4) for k, v in result.timings.items()},
    }
    say(f"{name}: {result.n_regions} regions from {len(result.hierarchy.maxima)} maxima; writing")
    # Everything goes into a hidden staging folder first and is renamed into place at
    # the end, so a failure (or Ctrl-C) leaves no partial output.
    staging = Path(tempfile.mkdtemp(prefix=".volseg-", dir=out_dir))
    try:
        # Labels in the smallest unsigned type that holds them (what label viewers
        # expect); the three writers run at once (zlib releases the GIL).
        label_type = np.min_scalar_type(max(result.n_regions - 1, 0))
        with ThreadPoolExecutor(3) as pool:
            jobs = [
                pool.submit(write_volume, staging / targets["labels"].name,
                            labels.astype(label_type), spacing=result.spacing),
                pool.submit(write_volume, staging / targets["curvature"].name,
                            result.curvature.astype(np.float32), spacing=result.spacing),
                pool.submit(write_preview, staging / targets["preview"].name, data,
                            result.curvature, labels,
                            title=f"{name}: {result.n_regions} regions, {result.operator} curvature"),
            ]
            for job in jobs:
                job.result()
        summary["timings_s"]["total"] = round(time.perf_counter() - started, 4)
        (staging / targets["summary"].name).write_text(json.dumps(summary, indent=2))
        for target in targets.values():
            os.replace(staging / target.name, target)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return summary


def _synthetic_volume(n=48):
    """Built-in demo volume: three Gaussian blobs and a curved ridge, uint8."""
    axis = np.linspace(-1, 1, n)
    x, y, z = np.meshgrid(axis, axis, axis, indexing="ij")
    f = np.zeros_like(x)
    for (cx, cy, cz), w, a in [((-0.4, -0.3, 0.1), 0.25, 1.0), ((0.45, 0.3, -0.2), 0.2, 0.8),
                               ((0.1, 0.5, 0.5), 0.15, 0.6)]:
        f += a * np.exp(-((x - cx) ** 2 + (y - cy) ** 2 + (z - cz) ** 2) / (2 * w * w))
    ridge = np.exp(-((y + 0.5 * x**2 - 0.55) ** 2 + (z + 0.5) ** 2) / (2 * 0.08**2))
    f += 0.5 * ridge
    return np.round(255 * f / f.max()).astype(np.uint8)


def _tagged(say, tag):
    return lambda message: say(tag + message)


def _cmd_segment(args):
    say = _progress(args.quiet)
    out_dir = Path(args.out_dir)
    _check_out_dir(out_dir)
    if args.regions is not None and args.regions < 1:
        raise UsageError(f"--regions must be at least 1, got {args.regions}")
    loaded = []
    for input_name in args.inputs:  # read and check everything before computing anything
        volume, path = _load(input_name, args.shape, args.dtype)
        loaded.append((volume, path))
    summaries = []
    for number, (volume, path) in enumerate(loaded, 1):
        step = say if len(loaded) == 1 else _tagged(say, f"[{number}/{len(loaded)}] ")
        summary = segment_to_files(
            volume, out_dir, name=volume.name, operator=args.operator.replace("-", "_"),
            n_regions=args.regions, min_persistence=args.min_persistence,
            value_scale=args.value_scale, noise=args.noise, seed=args.seed, force=args.force,
            source=path, say=step)
        summaries.append(summary)
        step(f"{volume.name}: wrote {', '.join(Path(p).name for p in summary['outputs'].values())}")
    if args.json:
        print(json.dumps(summaries if len(summaries) > 1 else summaries[0], indent=2))
    return 0


def _cmd_fetch(args):
    import data_fetch

    for name in args.names:
        print(data_fetch.fetch(name))
    return 0


def _cmd_demo(args):
    from .io import Volume

    out_dir = Path(args.out_dir)
    _check_out_dir(out_dir)
    volume = Volume(_synthetic_volume(), name="demo", source="built-in synthetic")
    summary = segment_to_files(volume, out_dir, name="demo", force=True, say=_progress(args.quiet))
    print(f"segmented a built-in {'x'.join(map(str, volume.shape))} volume into "
          f"{summary['n_regions']} regions; wrote:")
    for path in summary["outputs"].values():
        print(f"  {path}")
    return 0


def _cmd_info(args):
    volume, path = _load(args.input, args.shape, args.dtype)
    data = volume.data
    print(f"{path}\n  shape (x, y, z): {data.shape}\n  dtype: {data.dtype}\n"
          f"  range: {data.min()} .. {data.max()} (mean {data.mean():.4g})\n"
          f"  spacing: {volume.spacing}\n  read as: {volume.source}")
    return 0


def _cmd_compare(args):
    from . import metrics
    from .io import read_volume

    a = read_volume(args.labels_a).data
    b = read_volume(args.labels_b).data
    if a.dtype.kind == "f" or b.dtype.kind == "f":
        raise UsageError("label volumes must hold integer labels")
    result = metrics.compare(a, b)
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        for key, value in result.items():
            print(f"{key}: {value:.6g}" if isinstance(value, float) else f"{key}: {value}")
    return 0


def main(argv=None) -> int:
    parser = _get_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exit_:
        return int(exit_.code or 0)
    command = {"segment": _cmd_segment, "fetch": _cmd_fetch, "demo": _cmd_demo,
               "info": _cmd_info, "compare": _cmd_compare}[args.command]
    try:
        return command(args)
    except (ValueError, FileNotFoundError, PermissionError, IsADirectoryError) as err:
        print(f"volseg: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("volseg: interrupted", file=sys.stderr)
        return 130
    except Exception as err:  # noqa: BLE001 - the last resort, reported as such
        print(f"volseg: unexpected failure: {type(err).__name__}: {err}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
