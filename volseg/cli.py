"""The `volseg` command line: argparse only, every action is a library call.

Exit codes: 0 done, 2 bad input or usage (one line on stderr), 1 unexpected failure.
"""

from __future__ import annotations

import argparse
import re
import signal
import sys
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from . import _json, _validate
from ._version import __version__
from .blockwise.engine import MEMORY_SHARE, default_memory_limit, parse_bytes
from .curvature import REGISTRY as OPERATOR_REGISTRY
from .curvature import cli_choices, normalize_operator
from .errors import UsageError
from .fields import FIELD_REGISTRY
from .io.readers import INPUT_FORMATS
from .morse import MEASURES
from .segment import (
    AUTO_INTEGER_SIGMA,
    AUTO_REGION_RANGE,
    DEFAULT_MEASURE,
    DEFAULT_MIN_COMPONENT,
    DEFAULT_REGIONS,
)


def _get_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="volseg",
        description="Segment volumes by the mean curvature of their graph in R^4 and a "
        "persistence-simplified descending Morse complex.",
    )
    parser.add_argument("--version", action="version", version=f"volseg {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    _add_segment(sub)
    _add_isosurface(sub)
    _add_others(sub)
    return parser


#: The curvature operators, for --operator's help (the registry's labels).
OPERATOR_HELP = ("the curvature operator (with --field curvature): " + "; ".join(
    f"{op.name.replace('_', '-')}: {op.label}" for op in OPERATOR_REGISTRY.values())
    + " (default weighted, the paper's mean-curvature estimate)")

_MEASURE_HELP = (
    "what decides which regions survive the cut (default: the field's, "
    f"{DEFAULT_MEASURE} for curvature and value, volume for gradient, area where "
    "volume's cut is degenerate; persistence with --min-persistence): persistence keeps "
    "the tallest peaks (on 8-bit or noisy data, voxel-sized spikes); size the largest "
    "regions (the smallest merges into its neighbour across their highest saddle); "
    "hypervolume weighs size by height (Carr et al. 2004); area and volume are the "
    "watershed hierarchies (higra's): the smaller side's size or volume at each saddle")


def _add_segment(sub):
    seg = sub.add_parser("segment", help="segment volume files or named datasets")
    seg.add_argument("inputs", nargs="+", metavar="INPUT",
                     help=f"a volume ({INPUT_FORMATS}) or a dataset name")
    seg.add_argument("-o", "--out-dir", default=".", help="output folder (default: .)")
    operators, shown = cli_choices()
    seg.add_argument("--operator", choices=operators, metavar=shown, default="weighted",
                     help=OPERATOR_HELP)
    cut = seg.add_mutually_exclusive_group()
    cut.add_argument("--regions", type=_regions, metavar="K",
                     help=f"number of regions (default {DEFAULT_REGIONS}; with a mask, foreground "
                     f"regions), or 'auto': a count in {AUTO_REGION_RANGE[0]}-"
                     f"{AUTO_REGION_RANGE[1]} where the measure's curve has a gap that "
                     f"stands out from a power law, else {DEFAULT_REGIONS}")
    cut.add_argument("--min-persistence", type=float, metavar="T",
                     help="instead of a count: merge every peak of the curvature less "
                     "persistent than T (the persistence measure only)")
    cut.add_argument("--threshold", type=float, metavar="T",
                     help="instead of a count: merge every region whose --measure is below T "
                     "(size: in world units, voxels times the voxel volume)")
    seg.add_argument("--field", default="curvature", metavar="FIELD",
                     help="the field the regions are cut from: curvature (default, the "
                     "paper's: territories around curvature peaks), gradient (basins of "
                     "the gradient magnitude: regions bounded by edges, a watershed "
                     "hierarchy; best on anatomy and other piecewise-smooth scans), value "
                     "(bright blobs of the values; |value| on a signed map), or a volume "
                     "file of the same grid to cut as it is")
    seg.add_argument("--measure", choices=MEASURES, default=None, help=_MEASURE_HELP)
    seg.add_argument("--min-component", type=float, default=None, metavar="SHARE",
                     help="mask components smaller than this share of the mask are labelled 0 "
                     f"and use no region (default {DEFAULT_MIN_COMPONENT:g}; 0 keeps all)")
    masking = seg.add_mutually_exclusive_group()
    masking.add_argument("--mask", default="auto", metavar="RULE",
                         help="voxels to segment: auto (default: a plateau over half the "
                         "volume, at the minimum or a signed map's 0, is left out; else a "
                         "dominant low mode of the histogram, noisy air in CT or MRI, below "
                         "its triangle threshold; else nothing), none, nonzero, otsu, or "
                         "'value>T' (also >=, <, <=)")
    masking.add_argument("--mask-threshold", type=float, metavar="T",
                         help="segment the voxels with value > T (same as --mask 'value>T')")
    seg.add_argument("--smooth", "--smooth-sigma", dest="smooth_sigma", type=float, default=None,
                     metavar="SIGMA",
                     help="Gaussian pre-smoothing of the values, sigma in voxels; 0: none. "
                     f"Default: {AUTO_INTEGER_SIGMA:g} for integer data of up to 16 bits (their "
                     "quantization steps are voxel-sized curvature noise), 0 for floats. "
                     "Larger: fewer, rounder regions; features under about 2 SIGMA vanish")
    seg.add_argument("--vti", action=argparse.BooleanOptionalAction, default=None,
                     help="also write <name>_volumes.vti, the input, field and labels "
                     "for ParaView (a .vts grid with every voxel's position for an oblique "
                     "or flipped scan; default: up to 256^3 voxels)")
    seg.add_argument("--plot-persistence", action="store_true",
                     help="also write <name>_persistence.png, the persistence curve alone")
    seg.add_argument("--chunks", type=int, metavar="N",
                     help="segment block by block in chunks of N^3 voxels (the blockwise path, "
                     "always taken for Zarr input): labels and curvature are written as .zarr")
    _add_blockwise_options(seg)
    _add_segment_io(seg)


def _add_blockwise_options(seg):
    engine = seg.add_argument_group(
        "blockwise engine", "where the blockwise path (Zarr input, --chunks) runs its blocks")
    engine.add_argument("--scheduler", metavar="ADDRESS",
                        help="'threads' (default: Dask's threaded scheduler in this process, "
                        "the fastest on one machine), 'local' (a local dask.distributed cluster "
                        "with worker memory limits), or a running scheduler's address "
                        "(tcp://host:port)")
    engine.add_argument("--workers", type=int, metavar="N",
                        help="threads or local workers (default: one per core)")
    engine.add_argument("--threads-per-worker", type=int, metavar="N", default=1,
                        help="with --scheduler local: threads in each worker process "
                        "(default 1); threads of one worker share blocks without a transfer")
    engine.add_argument("--memory-limit", metavar="BYTES",
                        help="memory budget, e.g. 12GB or 0.5 (a share of RAM; default "
                        f"{MEMORY_SHARE:g} of this machine's RAM): an input whose in-memory run "
                        "would need more (about 40 bytes per voxel) is segmented block by block; "
                        "also the local cluster's worker limits together")
    engine.add_argument("--hierarchy-memory", metavar="BYTES",
                        help="with --scheduler local: one more worker, of this memory, the only "
                        "one to hold the whole Morse hierarchy (its join and its cut, about 150 "
                        "bytes per maximum), so that the other workers can stay small")


def _add_segment_io(seg):
    seg.add_argument("--shape", type=int, nargs=3, metavar=("X", "Y", "Z"))
    seg.add_argument("--dtype", help="voxel type of raw input (uint8, uint16, float32, ...)")
    seg.add_argument("--value-scale", type=float, metavar="S",
                     help="scale of the value axis (default: graph as tall as it is wide)")
    seg.add_argument("--noise", type=float, metavar="SIGMA_PERCENT",
                     help="add Gaussian noise, sigma in percent of the value range")
    seg.add_argument("--seed", type=int, default=0, help="seed of --noise (default 0)")
    seg.add_argument("--force", action="store_true", help="overwrite existing outputs")
    seg.add_argument("--wait", action="store_true",
                     help="wait for another volseg writing the same outputs (default: fail)")
    seg.add_argument("--allow-external-data", action="store_true",
                     help="let a detached header (.nhdr, .dat) name a data file outside its "
                     "folder, or a Zarr store hold links to files outside it")
    seg.add_argument("--fill-missing-chunks", action="store_true",
                     help="read a Zarr store's unwritten chunks as its fill value, as Zarr "
                     "does (default: refused, since an interrupted copy looks the same)")
    seg.add_argument("--channel", type=int, metavar="C",
                     help="the channel of an OME-Zarr image with several (its 'c' axis)")
    seg.add_argument("--ome-level", type=int, metavar="L",
                     help="the resolution level of an OME-Zarr image (default 0, the full one)")
    seg.add_argument("--labels-into-input", nargs="?", const="volseg", metavar="NAME",
                     help="also add the labels to an OME-Zarr input image, as its NGFF labels "
                     "image labels/NAME (default volseg), where napari-ome-zarr and NGFF "
                     "viewers find them (the input is otherwise never written)")
    seg.add_argument("--json", action="store_true", help="print the summaries as JSON on stdout")
    seg.add_argument("-q", "--quiet", action="store_true", help="no progress on stderr")


def _add_isosurface(sub):
    operators, shown = cli_choices()
    iso = sub.add_parser(
        "isosurface", help="segment the space-time isosurface of a time-varying volume",
        description="Extract the isosurface {F = LEVEL} of a time series F(x, y, z, t) as a "
        "tetrahedral 3-manifold in R^4, compute its mean curvature and segment it by the "
        "descending Morse complex; writes the mesh (.npz), a ParaView time series (.pvd + "
        ".vtu per step), a summary and a preview of three time steps.")
    iso.add_argument("inputs", nargs="+", metavar="INPUT",
                     help="one 4-D .npy / .nii(.gz) / .zarr (x, y, z, t), or 3-D volumes in time "
                     "order (a quoted glob is sorted by name)")
    iso.add_argument("--level", type=float, required=True, metavar="L", help="isosurface value")
    iso.add_argument("--time-scale", type=float, default=1.0, metavar="S",
                     help="length of one time step in R^4, in voxel-size units (default 1)")
    iso.add_argument("--time-step", type=float, metavar="DT",
                     help="time between two steps, for the ParaView series' time values "
                     "(default: a 4-D NIfTI's pixdim[4], else 1)")
    iso.add_argument("-o", "--out-dir", default=".", help="output folder (default: .)")
    iso.add_argument("--name", help="output stem (default: the first input's name)")
    iso.add_argument("--operator", choices=operators, metavar=shown, default="weighted")
    iso_cut = iso.add_mutually_exclusive_group()
    iso_cut.add_argument("--regions", type=_regions, metavar="K",
                         help="number of regions, or 'auto' (default 30)")
    iso_cut.add_argument("--min-persistence", type=float, metavar="T")
    iso.add_argument("--relax", type=int, default=10, metavar="N",
                     help="mesh-quality rounds (tangential relaxation + projection onto the "
                     "level set; 0: the raw marching mesh; default 10)")
    iso.add_argument("--smooth-rounds", "--smooth", dest="smooth_rounds", type=int, default=10,
                     metavar="N", help="rounds of 1-ring averaging of the curvature before the "
                                       "Morse "
                     "stage (the paper smooths estimates on irregular meshes; default 10, "
                     "0: none)")
    iso.add_argument("--boundary", choices=("partial", "nan"), default="partial",
                     help="curvature at vertices where the surface meets the grid's edge: "
                     "over their partial star (default), or left out with label 0")
    iso.add_argument("--force", action="store_true", help="overwrite existing outputs")
    iso.add_argument("--wait", action="store_true",
                     help="wait for another volseg writing the same outputs")
    iso.add_argument("--allow-external-data", action="store_true")
    iso.add_argument("--memory-limit", metavar="BYTES",
                     help="memory budget, e.g. 12GB or 0.5 (a share of RAM; default "
                     f"{MEMORY_SHARE:g} of this machine's RAM): a level cutting more grid cells "
                     "than fit (about 64 KB each) is refused before the surface is made")
    iso.add_argument("--json", action="store_true", help="print the summary as JSON on stdout")
    iso.add_argument("-q", "--quiet", action="store_true", help="no progress on stderr")


def _add_others(sub):
    fetch = sub.add_parser("fetch", help="download and verify named datasets")
    fetch.add_argument("names", nargs="+", metavar="NAME")

    demo = sub.add_parser("demo", help="segment a built-in synthetic volume (offline)")
    demo.add_argument("-o", "--out-dir", default="volseg-demo")
    demo.add_argument("--time", action="store_true",
                      help="the time-varying demo: two blobs that drift and merge, segmented "
                      "as a space-time isosurface")
    demo.add_argument("--force", action="store_true", help="overwrite existing outputs")
    demo.add_argument("-q", "--quiet", action="store_true")

    info = sub.add_parser("info", help="describe a volume file or dataset")
    info.add_argument("input", metavar="INPUT")
    info.add_argument("--shape", type=int, nargs=3, metavar=("X", "Y", "Z"))
    info.add_argument("--dtype")
    info.add_argument("--allow-external-data", action="store_true")
    info.add_argument("--fill-missing-chunks", action="store_true")
    info.add_argument("--channel", type=int, metavar="C")
    info.add_argument("--ome-level", type=int, metavar="L")

    compare = sub.add_parser("compare", help="compare two label volumes (Huang-Dom)")
    compare.add_argument("labels_a", metavar="LABELS_A")
    compare.add_argument("labels_b", metavar="LABELS_B")
    compare.add_argument("--mask", metavar="MASK",
                         help="score only the voxels where this volume is nonzero (a mask, or "
                         "a label volume whose 0 is background); 'a' or 'b': the foreground "
                         "(labels > 0) of that input")
    compare.add_argument("--any-grid", action="store_true",
                         help="compare voxel by voxel even when the files place their voxels "
                         "differently (voxel sizes, origin, axes or unit); refused otherwise")
    compare.add_argument("--json", action="store_true")


def _regions(text):
    if text == "auto":
        return text
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError("expected a number of regions or 'auto', got "
                                         f"{text!r}") from None


def _progress(quiet):
    def say(message):
        if not quiet:
            print(f"volseg: {message}", file=sys.stderr, flush=True)
    return say


#: The library's keyword -> this command line's option, for the library's messages.
_OPTIONS = {"n_regions": "--regions", "min_persistence": "--min-persistence",
            "threshold": "--threshold", "measure": "--measure", "min_component": "--min-component",
            "smooth_sigma": "--smooth", "mask": "--mask", "chunks": "--chunks",
            "operator": "--operator", "value_scale": "--value-scale", "smooth_rounds": "--smooth",
            "field": "--field"}


def _checked_request(**options):
    """`volseg.segment.SegmentRequest.checked` of the options, before any input is read:
    its error becomes a `UsageError` that names our options (``--regions``, not
    ``n_regions``)."""
    from .segment import SegmentRequest

    try:
        return SegmentRequest.checked(**options)
    except ValueError as err:
        message = str(err)
        for keyword, option in _OPTIONS.items():
            message = message.replace(f"`{keyword}`", option)
        raise UsageError(message) from None


def _cut_options(args) -> dict:
    """The cut's options of `segment` and `isosurface`, as the library names them."""
    return {"n_regions": args.regions, "min_persistence": args.min_persistence,
            **{name: getattr(args, name, None) for name in ("measure", "threshold",
                                                            "min_component")}}


def _cmd_segment(args):
    say = _progress(args.quiet)
    out_dir = Path(args.out_dir)
    with _removed_if_left_empty(out_dir):
        return _segment(args, say, out_dir)


@contextmanager
def _removed_if_left_empty(out_dir: Path):
    """Remove `out_dir` when this command created it and fails leaving it empty."""
    existed = out_dir.exists()
    try:
        yield
    except BaseException:
        if not existed and out_dir.is_dir() and not any(out_dir.iterdir()):
            out_dir.rmdir()
        raise


def _segment(args, say, out_dir: Path):
    from .blockwise.engine import Engine
    from .files import load_for_budget, segment_files

    mask = args.mask if args.mask_threshold is None else f"value>{args.mask_threshold!r}"
    field = args.field if FIELD_REGISTRY.get(args.field) else None    # else a file
    request = _checked_request(**_cut_options(args), operator=args.operator, mask=mask,
                               smooth_sigma=args.smooth_sigma, value_scale=args.value_scale,
                               chunks=args.chunks, field=field or "curvature")
    engine = Engine(args.scheduler, workers=args.workers, memory_limit=args.memory_limit,
                    hierarchy_memory=args.hierarchy_memory,
                    threads_per_worker=args.threads_per_worker,
                    progress=not args.quiet and sys.stderr.isatty())   # arguments checked here
    engine.check()
    # Read and check every input before writing or computing anything.
    volumes = [load_for_budget(name, engine.memory_limit, shape=args.shape, dtype=args.dtype,
                               allow_external_data=args.allow_external_data,
                               fill_missing_chunks=args.fill_missing_chunks,
                               chunks=request.chunks, channel=args.channel,
                               ome_level=args.ome_level, say=say)
               for name in args.inputs]
    if field is None:                       # a field of the user's, read like an input
        field = load_for_budget(args.field, engine.memory_limit, chunks=request.chunks,
                                allow_external_data=args.allow_external_data).data
    summaries = segment_files(
        volumes, out_dir, force=args.force, wait=args.wait,
        persistence_plot=args.plot_persistence, paraview=args.vti, engine=engine, say=say,
        operator=normalize_operator(args.operator), n_regions=args.regions,
        min_persistence=args.min_persistence, value_scale=args.value_scale, noise=args.noise,
        seed=args.seed, mask=mask, smooth_sigma=args.smooth_sigma, measure=args.measure,
        threshold=args.threshold, min_component=args.min_component,
        labels_into_input=args.labels_into_input, ome_level=args.ome_level, field=field)
    if args.json:
        print(_json.dumps(summaries if len(summaries) > 1 else summaries[0], indent=2))
    return 0


def _cmd_isosurface(args):
    from .files import segment_series_files
    from .io.series import read_series

    say = _progress(args.quiet)
    out_dir = Path(args.out_dir)
    _checked_request(**_cut_options(args), operator=args.operator)
    if not (np.isfinite(args.level)):
        raise UsageError(f"--level must be a finite number, got {args.level}")
    _validate.step(args.time_scale, "--time-scale")
    if args.relax < 0 or args.smooth_rounds < 0:
        raise UsageError(f"--relax and --smooth must be numbers of rounds >= 0, got "
                         f"{args.relax} and {args.smooth_rounds}")
    series = read_series(args.inputs, allow_external_data=args.allow_external_data)
    if args.name:
        if not args.name.strip() or "/" in args.name or args.name.startswith("."):
            raise UsageError(f"--name must be a plain file stem, got {args.name!r}")
        series.name = args.name
    if args.time_step is not None:
        series.time_step = _validate.number(args.time_step, "--time-step", positive=True)
    lo, hi = float(np.min(series.data)), float(np.max(series.data))
    if not lo < args.level <= hi:
        raise UsageError(f"--level {args.level:g} is not crossed: the series ranges over "
                         f"[{lo:g}, {hi:g}]")
    summary = segment_series_files(
        series, args.level, out_dir, force=args.force, wait=args.wait, say=say,
        time_scale=args.time_scale, relax=args.relax, operator=normalize_operator(args.operator),
        n_regions=args.regions, min_persistence=args.min_persistence, boundary=args.boundary,
        smooth_rounds=args.smooth_rounds,
        memory_limit=default_memory_limit() if args.memory_limit is None
        else parse_bytes(args.memory_limit))
    if args.json:
        print(_json.dumps(summary, indent=2))
    return 0


def _cmd_fetch(args):
    from .datasets import fetch

    for name in args.names:
        print(fetch(name))
    return 0


def _cmd_demo(args):
    from .datasets import demo_volume
    from .files import segment_files
    from .io import Volume

    out_dir = Path(args.out_dir)
    if args.time:
        return _demo_time(args, out_dir)
    volume = Volume(demo_volume(), name="demo", source="built-in synthetic")
    summary, = segment_files([volume], out_dir, force=args.force, say=_progress(args.quiet),
                             mask="auto", n_regions=DEMO_REGIONS)
    print(f"segmented a built-in {'x'.join(map(str, volume.shape))} volume into "
          f"{summary['n_regions']} regions; wrote:")
    for path in summary["outputs"].values():
        print(f"  {path}")
    return 0


#: Regions of `volseg demo --time`: each blob's cap, the neck and the merged blob's ends.
DEMO_TIME_REGIONS = 6
#: The demo volume holds three blobs and a ridge: 8 regions show them and their parts
#: (30 would be mostly slivers between them, a degenerate cut).
DEMO_REGIONS = 8


def _demo_time(args, out_dir):
    from .datasets import demo_series
    from .files import segment_series_files
    from .io.series import Series

    data = demo_series()
    step = 2.0 / (data.shape[0] - 1)
    series = Series(data, (step, step, step), "demo_time", (), None)
    summary = segment_series_files(series, 0.5, out_dir, force=args.force,
                                   say=_progress(args.quiet), time_scale=step,
                                   n_regions=DEMO_TIME_REGIONS)
    print(f"segmented the space-time isosurface of a built-in "
          f"{'x'.join(map(str, data.shape))} series (two blobs merging) into "
          f"{summary['n_regions']} regions; wrote:")
    for kind, path in summary["outputs"].items():
        if not kind.startswith("t0") or kind == "t0000":
            print(f"  {path}" + (" (one .vtu per time step)" if kind == "t0000" else ""))
    return 0


def _cmd_info(args):
    from .files import load_volume

    volume = load_volume(args.input, args.shape, args.dtype, args.allow_external_data,
                         channel=args.channel, ome_level=args.ome_level,
                         fill_missing_chunks=args.fill_missing_chunks)
    data = volume.data
    frame = volume.frame
    if hasattr(data, "compute"):          # a Zarr store: one pass over its chunks
        import dask

        low, high, mean = (v.item() for v in dask.compute(data.min(), data.max(), data.mean()))
    else:
        low, high, mean = data.min(), data.max(), data.mean()
    affine = "\n".join("    " + " ".join(f"{v:10.4g}" for v in row) for row in frame.affine)
    print(f"{volume.path}\n  shape (x, y, z): {data.shape}\n  dtype: {data.dtype}\n"
          f"  range: {low} .. {high} (mean {mean:.4g})\n"
          f"  spacing: {volume.spacing} ({frame.unit or 'unit unknown'})\n"
          f"  voxel-to-world affine (RAS+, sform code "
          f"{frame.sform_code}, qform code {frame.qform_code}):\n{affine}\n"
          f"  read as: {volume.source}\n  files: {', '.join(map(str, volume.files))}")
    return 0


def _integer_labels(data, path):
    """Labels as integers: float files of whole numbers (FSL writes label maps as
    float32) taken as they are, anything else refused naming the file."""
    data = np.asarray(data)
    if data.dtype.kind != "f":
        return data
    whole = np.isfinite(data) & (data == np.round(data))
    if not whole.all():
        first = tuple(int(i) for i in np.argwhere(~whole)[0])
        raise UsageError(f"{path}: label volumes must hold integer labels, got {data.dtype} "
                         f"{float(data[first]):g} at voxel {list(first)}")
    return data.astype(np.int64)


def _frame_text(frame) -> str:
    spacing = ", ".join(f"{v:g}" for v in frame.spacing)
    origin = ", ".join(f"{v:g}" for v in frame.affine[:3, 3])
    return (f"voxel sizes ({spacing}) {frame.unit or 'no unit'}, origin ({origin})"
            + ("" if frame.axis_aligned else ", rotated or flipped"))


def _same_grid_or_say(first, other, name: str, any_grid: bool):
    """Refuse labels (or a mask) whose voxels sit elsewhere than the first labels'
    (`Frame.agrees_with`): a voxel-by-voxel score of two grids compares different
    places. `any_grid` (a user who knows) compares them anyway, saying so."""
    import warnings

    from .errors import VolsegWarning

    if first.frame.agrees_with(other.frame):
        return
    what = (f"{name} places its voxels elsewhere than the first labels ("
            f"{_frame_text(other.frame)}, against {_frame_text(first.frame)})")
    if not any_grid:
        raise UsageError(f"{what}: resample one onto the other's grid, or pass --any-grid "
                         "to compare them voxel by voxel as they are")
    warnings.warn(f"{what}: compared voxel by voxel as they are (--any-grid)", VolsegWarning,
                  stacklevel=2)


def _cmd_compare(args):
    from . import metrics
    from .files import load_volume

    volume_a, volume_b = load_volume(args.labels_a), load_volume(args.labels_b)
    a = _integer_labels(volume_a.data, args.labels_a)
    b = _integer_labels(volume_b.data, args.labels_b)
    if a.shape != b.shape:
        raise UsageError(f"{args.labels_a} is {a.shape} but {args.labels_b} is {b.shape}")
    _same_grid_or_say(volume_a, volume_b, args.labels_b, args.any_grid)
    mask = None
    if args.mask:
        mask = {"a": a, "b": b}.get(args.mask)
        if mask is None:
            volume_mask = load_volume(args.mask)
            _same_grid_or_say(volume_a, volume_mask, f"--mask {args.mask}", args.any_grid)
            mask = volume_mask.data
        mask = np.asarray(mask) != 0
        if mask.shape != a.shape:
            raise UsageError(f"--mask {args.mask} is {mask.shape}, the labels are {a.shape}")
    result = metrics.compare(a, b, mask=mask)
    if args.json:
        print(_json.dumps(result, indent=2))
    else:
        for key, value in result.items():
            print(f"{key}: {value:.6g}" if isinstance(value, float) else f"{key}: {value}")
    return 0


#: The exit code of an interrupted run (Ctrl-C or SIGTERM), as a shell reports SIGINT.
INTERRUPTED = 130


def _raise_interrupt(signum, frame):
    signal.signal(signal.SIGTERM, signal.SIG_IGN)     # once: the unwinding is not cut short
    raise KeyboardInterrupt


def main(argv=None) -> int:
    """Run the command line on `argv` (default ``sys.argv[1:]``); returns the exit code."""
    parser = _get_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exit_:
        return int(exit_.code or 0)
    command = {"segment": _cmd_segment, "isosurface": _cmd_isosurface, "fetch": _cmd_fetch,
               "demo": _cmd_demo, "info": _cmd_info, "compare": _cmd_compare}[args.command]
    # SIGTERM unwinds like Ctrl-C: staging folders are removed, locks released.
    previous = signal.signal(signal.SIGTERM, _raise_interrupt)
    try:
        with _quiet_readers():
            return command(args)
    except (ValueError, OSError) as err:  # VolumeFileError, OutputError, UsageError, paths
        print(f"volseg: error: {_disk_full(err, args) or _one_line(err)}", file=sys.stderr)
        return 2
    except MemoryError:
        print("volseg: error: not enough memory for this volume", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("volseg: interrupted", file=sys.stderr)
        return INTERRUPTED
    except Exception as err:  # noqa: BLE001 - the last resort, reported as such
        print(f"volseg: unexpected failure (a bug; please report it): {type(err).__name__}: "
              f"{_one_line(err)}", file=sys.stderr)
        return 1
    finally:
        signal.signal(signal.SIGTERM, previous)


@contextmanager
def _quiet_readers():
    """Nibabel's and Zarr's warnings and log lines (header fix-ups, metadata they do
    not recognise) off the terminal: what volseg refuses it says in its own one line,
    and what it accepts needs no second."""
    import logging
    import warnings

    from .errors import VolsegWarning

    logger = logging.getLogger("nibabel")
    level = logger.level
    logger.setLevel(logging.CRITICAL)
    try:
        with warnings.catch_warnings():
            for module in ("nibabel", "zarr", "numcodecs", "ome_zarr"):
                warnings.filterwarnings("ignore", module=module + r"(\..*)?")
            # volseg's own warnings (a degenerate cut, fewer maxima than regions): one
            # line on stderr each, even with -q, never Python's two-line form.
            warnings.simplefilter("always", VolsegWarning)
            shown = warnings.showwarning

            def one_line(message, category, *args, **kwargs):
                if issubclass(category, VolsegWarning):
                    print(f"volseg: warning: {message}", file=sys.stderr, flush=True)
                else:
                    shown(message, category, *args, **kwargs)

            warnings.showwarning = one_line
            try:
                yield
            finally:
                warnings.showwarning = shown
    finally:
        logger.setLevel(level)


def run():
    """The ``volseg`` command: `main`, then the process's exit with its code.

    After an interrupt everything is cleaned up already (staging removed, lock
    released), but the interrupt can land in the middle of an import, and finishing
    the interpreter over a half-imported module can end the process by SIGINT
    instead of this exit code: that exit skips the interpreter's finalization."""
    import os

    code = main()
    if code == INTERRUPTED:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    sys.exit(code)


def _disk_full(err, args) -> str | None:
    """A full disk as the folder that filled, not numpy's "32768 requested and 1008
    written" or an errno without a file name; None for any other error."""
    import errno
    import shutil

    if not isinstance(err, OSError):
        return None
    short_write = err.errno is None and re.fullmatch(r"\d+ requested and \d+ written",
                                                       str(err))
    if not (err.errno == errno.ENOSPC or short_write):
        return None
    folder = Path(getattr(args, "out_dir", None) or err.filename or ".")
    try:
        free = f" ({shutil.disk_usage(folder).free / 1e9:.3g} GB free)"
    except OSError:
        free = ""
    return (f"{folder}: the disk is full{free}; nothing was committed, and a blockwise "
            "run's finished blocks are kept: free some space and run again to resume, or "
            "write the outputs elsewhere (-o)")


def _one_line(err) -> str:
    """An exception as one line: OSErrors with their file, everything else as is."""
    if isinstance(err, OSError) and err.filename and err.strerror:
        return f"{err.filename}: {err.strerror}"
    return " ".join(str(err).split())


if __name__ == "__main__":
    run()
