"""Stability of segmentations under value noise (the paper's Fig. 5), on Dask.

    python -m pipelines.noise_stability --out runs/fig5            # run (or resume)
    python -m pipelines.noise_stability --out runs/fig5 --report   # run, then CSV + figure

Per dataset and operator, the persistence threshold that cuts the clean volume into
`--regions` regions (default 30, the paper's 20-40) and the value scale of the clean
volume are fixed once. Each task adds seeded Gaussian noise (sigma = level % of the
clean value range), recomputes curvature and segmentation with that threshold and
scale, and scores the result against the clean segmentation (Huang-Dom similarity,
both directional distances, region-number ratio, region count).

With ``--cut defaults`` the protocol is a user's instead: the clean volume and each
noisy one are segmented with every default re-estimated on that volume (mask,
smoothing, the field's measure) into `--regions` regions, on each field of
``--fields``, and scored over every voxel (label 0 outside a mask included).

Noise is "common random numbers": for one dataset and seed the same standard normal
field is scaled to every level, and every operator sees the same noisy volumes, so
curves differ by the operator and the level, not by the draw.

Tasks run on dask.distributed (a LocalCluster with one single-threaded worker per
core by default, or `--scheduler ADDRESS`). Each volume is scattered to the cluster
once and each clean reference is computed once on the cluster; tasks depend on both.
Every finished task is committed to ``<out>/results.sqlite`` at once, keyed by the
parameters that define it: a rerun skips finished tasks, an interrupted run loses
only the tasks in flight, a failed task is recorded with its error (and retried by
the next run) without stopping the others.
"""

from __future__ import annotations

import argparse
import sqlite3
import sys
import time
import uuid
import warnings
import zlib
from pathlib import Path

import numpy as np

from volseg.curvature import REGISTRY, cli_choices, normalize_operator
from volseg.errors import UsageError, VolsegWarning
from volseg.fields import FIELDS
from volseg.segment import DEFAULT_REGIONS

from ._output import save_figure, write_csv
from .store import ResultStore

DEFAULT_DATASETS = ("fuel", "neghip", "silicium")
DEFAULT_OPERATORS = ("laplace_beltrami", "weighted", "unweighted")
DEFAULT_LEVELS = (0.0, 0.1, 0.25, 0.5, 1.0, 2.0, 5.0, 10.0)
DEFAULT_SEEDS = 5
KEY_COLUMNS = ("dataset", "checksum", "operator", "field", "regions", "cut", "mask", "level",
               "seed")
MASKS = ("none", "auto")
CUTS = ("threshold", "regions", "defaults")
#: Line colours of the fields in the defaults figure.
FIELD_COLOURS = {"curvature": "#1f77b4", "gradient": "#d62728", "value": "#2ca02c"}
DB_NAME = "results.sqlite"


# ---------------------------------------------------------------- the task itself


def noisy_volume(volume, level, seed, dataset, value_range):
    """The clean volume (float64) plus seeded Gaussian noise of `level` % of `value_range`.

    The draw depends on (seed, dataset) only, never on the level or the worker.
    """
    data = np.asarray(volume, dtype=np.float64)
    if level == 0:
        return data.copy()
    from volseg.noise import add_value_noise

    entropy = [int(seed), zlib.crc32(dataset.encode())]
    return add_value_noise(data, level, seed=np.random.default_rng(np.random.SeedSequence(entropy)),
                           reference_range=value_range)


def _single_threaded(threads):
    try:
        import numba

        numba.set_num_threads(max(1, min(int(threads), numba.config.NUMBA_NUM_THREADS)))
    except (ImportError, ValueError):  # pragma: no cover - numba is a dependency
        pass


def clean_reference(volume, operator, regions, mask="none", threads=1, field="curvature",
                    cut="threshold"):
    """Threshold, value scale, labels and mask of the clean segmentation into `regions`.

    With ``mask="auto"`` the mask is resolved on the clean volume and held for every
    noisy run (noise would make a value rule select everything): the foreground is
    a property of the data, not of the draw. With ``cut="defaults"``, the clean
    volume as it is, segmented on `field` with every default (`_defaults_run`).
    """
    from volseg import segment_volume

    _single_threaded(threads)
    data = np.asarray(volume)
    if cut == "defaults":
        clean = _defaults_run(data, operator, field, regions)
        return {"threshold": None, "value_scale": clean.value_scale,
                "n_regions": clean.n_regions, "labels": clean.labels, "mask": None,
                "value_range": float(data.max()) - float(data.min()),
                "measure": clean.measure, "smooth_sigma": clean.smooth_sigma}
    # The paper's cut: persistence, no pre-smoothing (volseg's defaults for scans differ).
    # Such a cut may be degenerate; the table reports its spread, so no warning here.
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", VolsegWarning)
        clean = segment_volume(np.asarray(volume, dtype=np.float64), operator=operator,
                               n_regions=regions, mask=mask, measure="persistence",
                               smooth_sigma=0)
    return {"threshold": clean.min_persistence, "value_scale": clean.value_scale,
            "n_regions": clean.n_regions, "labels": clean.labels, "mask": clean.mask.mask,
            "value_range": float(data.max()) - float(data.min())}


def _defaults_run(data, operator, field, regions):
    """`data` segmented as a user runs it: every default, re-estimated on it."""
    from volseg import segment_volume

    with warnings.catch_warnings():          # a degenerate cut shows in the spread
        warnings.simplefilter("ignore", VolsegWarning)
        return segment_volume(data, operator=operator, field=field, n_regions=regions)


def _failure(err) -> dict:
    return {"error": f"{type(err).__name__}: {' '.join(str(err).split())}"}


def clean_reference_safely(volume, operator, regions, mask="none", threads=1,
                           field="curvature", cut="threshold"):
    """`clean_reference`, with a failure returned as ``{"error": ...}`` (see below)."""
    try:
        return clean_reference(volume, operator, regions, mask, threads, field, cut)
    except Exception as err:  # noqa: BLE001 - reported in the rows of its tasks
        return _failure(err)


def run_task_safely(task, volume, reference, threads=1):
    """`run_task`, with a failure (its own or its reference's) returned as
    ``{"error": "Type: message"}`` instead of raised, so it is stored in the task's
    row and reported once, not logged by a worker as a traceback."""
    if "error" in reference:
        return reference
    try:
        return run_task(task, volume, reference, threads)
    except Exception as err:  # noqa: BLE001 - any failure of one task is that task's result
        return _failure(err)


def run_task(task, volume, reference, threads=1):
    """One noisy segmentation scored against the clean one: the task's row.

    Deterministic: the same task, volume and reference give the same row (but for
    the time) on any worker.
    """
    from volseg import compare, segment_volume

    _single_threaded(threads)
    start = time.perf_counter()
    data = noisy_volume(volume, task["level"], task["seed"], task["dataset"],
                        reference["value_range"])
    # The paper's rule holds the clean threshold; "regions" cuts the noisy hierarchy
    # into the clean region count instead, so only the boundaries can move; "defaults"
    # re-estimates everything on the noisy volume, as a user's run would.
    cut = ({"n_regions": reference["n_regions"]} if task.get("cut") == "regions"
           else {"min_persistence": reference["threshold"]})
    mask = reference["mask"]
    if task.get("cut") == "defaults":
        result = _defaults_run(data, task["operator"], task["field"], task["regions"])
    else:
        with warnings.catch_warnings():          # the paper's cut, its spread in the table
            warnings.simplefilter("ignore", VolsegWarning)
            result = segment_volume(data, operator=task["operator"],
                                    value_scale=reference["value_scale"], mask=mask,
                                    measure="persistence", smooth_sigma=0, **cut)
    clean = reference["labels"]
    scores = compare(clean, result.labels, mask=mask)  # a masked run scores its foreground
    # Plateaus (fuel and neghip are about half exact zeros) have zero curvature, so
    # their clean partition is decided by index tie-breaking and any noise redraws
    # it: the similarity over the foreground (clean value above its minimum) shows
    # how much of the drift is that.
    clean_values = np.asarray(volume)
    foreground = clean_values > clean_values.min()
    inside = compare(clean[foreground], result.labels[foreground]) if foreground.any() else scores
    return {
        **task,
        "similarity": scores["hamming_similarity"],
        "similarity_foreground": inside["hamming_similarity"],
        "foreground_fraction": float(foreground.mean()),
        # D_H(clean => noisy) and the reverse, as fractions of the voxels
        "d_clean_to_noisy": scores["directional_hamming_a_to_b"] / clean.size,
        "d_noisy_to_clean": scores["directional_hamming_b_to_a"] / clean.size,
        "region_ratio": scores["region_ratio"],
        "n_regions": result.n_regions,
        "clean_regions": reference["n_regions"],
        "threshold": reference["threshold"],
        "value_scale": reference["value_scale"],
        "measure": result.measure,
        "largest_share": float(np.bincount(result.labels[result.labels > 0]).max(initial=0)
                               / max(int((result.labels > 0).sum()), 1)),
        "seconds": time.perf_counter() - start,
    }


# ---------------------------------------------------------------- inputs


def load_dataset(spec):
    """(name, volume array, sha256 of every file read) of a dataset name or a volume path."""
    from volseg.datasets import resolve
    from volseg.io import read_volume
    from volseg.outputs import files_sha256

    try:
        volume = read_volume(resolve(spec))
    except (FileNotFoundError, ValueError) as err:  # DatasetError is a ValueError
        raise UsageError(str(err)) from None
    return volume.name, np.asarray(volume), files_sha256(volume.files)


def plan(datasets, operators, levels, seeds, regions, cut="threshold", mask="none",
         fields=("curvature",)):
    """All tasks, as dictionaries of the key columns, in a stable order. A field that
    is not the curvature reads no operator: it runs once, with the first."""
    from volseg.fields import get_field

    pairs = [(field, operator) for field in fields
             for operator in (operators if get_field(field).needs_scale else operators[:1])]
    return [
        {"dataset": name, "checksum": checksum, "operator": operator, "field": field,
         "regions": regions, "cut": cut, "mask": mask, "level": float(level), "seed": seed}
        for name, _, checksum in datasets for field, operator in pairs
        for level in levels for seed in range(seeds)
    ]


# ---------------------------------------------------------------- the run


def _store(out_dir):
    try:
        return ResultStore(Path(out_dir) / DB_NAME, KEY_COLUMNS)
    except ValueError as err:
        raise UsageError(str(err)) from None


def _engine(scheduler, workers):
    """The run's `volseg.blockwise.engine.Engine`, entered: a LocalCluster of single-threaded
    worker processes (one per core) or the running scheduler at `scheduler`."""
    from volseg.blockwise.engine import Engine, EngineError

    try:
        return Engine(scheduler or "local", workers=workers).__enter__()
    except EngineError as err:
        raise UsageError(f"--scheduler {scheduler}: {' '.join(str(err).split())}") from None


class _Progress:
    """One stderr line per ~5 % of the tasks (and the last), with rate and time left."""

    def __init__(self, total, say):
        self.total, self.say, self.done, self.failed = total, say, 0, 0
        self.start = time.perf_counter()
        self.step = max(1, total // 20)

    def tick(self, failed=False):
        self.done += 1
        self.failed += failed
        if self.done % self.step and self.done != self.total:
            return
        elapsed = time.perf_counter() - self.start
        left = elapsed / self.done * (self.total - self.done)
        self.say(f"{self.done}/{self.total} tasks ({self.failed} failed), "
                 f"{elapsed:.0f} s elapsed, about {left:.0f} s left")


def run(datasets, out_dir, *, operators=DEFAULT_OPERATORS, levels=DEFAULT_LEVELS,
        seeds=DEFAULT_SEEDS, regions=DEFAULT_REGIONS, cut="threshold", mask="none", scheduler=None,
        workers=None, fields=("curvature",),
        say=lambda message: None) -> dict:
    """Run (or resume) the tasks not yet done; returns counts of what happened.

    `datasets` are loaded `(name, volume, checksum)` triples (see `load_dataset`);
    `cut` is "threshold" (the paper: the clean threshold, held fixed) or "regions"
    (each noisy hierarchy cut into the clean region count).
    """
    if cut not in CUTS:
        raise UsageError(f"cut must be one of {CUTS}, got {cut!r}")
    from volseg.io import FolderLock, OutputError

    out_dir = Path(out_dir)
    if mask not in MASKS:
        raise UsageError(f"mask must be one of {MASKS}, got {mask!r}")
    if cut != "defaults" and tuple(fields) != ("curvature",):
        raise UsageError("--fields other than curvature need --cut defaults (the paper's "
                         "protocol is the curvature's)")
    if cut == "defaults" and mask != "none":
        raise UsageError("--cut defaults chooses its own mask; leave --mask none")
    tasks = plan(datasets, operators, levels, seeds, regions, cut, mask, fields)
    out_dir.mkdir(parents=True, exist_ok=True)
    lock = FolderLock(out_dir, "results", busy="another noise-stability run is using it")
    try:
        lock.acquire()  # two runs on one folder would compute the same tasks twice
    except OutputError as err:
        raise UsageError(str(err)) from None
    with lock, _store(out_dir) as store:
        done = store.done_keys()
        pending = [t for t in tasks if store.key(t) not in done]
        counts = {"tasks": len(tasks), "already_done": len(tasks) - len(pending), "ran": 0,
                  "failed": 0, "seconds": 0.0}
        if not pending:
            say(f"nothing to do: all {len(tasks)} tasks are in {store.path}")
            return counts
        say(f"{len(pending)} of {len(tasks)} tasks to run "
            f"({counts['already_done']} already in {store.path})")
        start = time.perf_counter()
        progress = _Progress(len(pending), say)
        engine = _engine(scheduler, workers)
        try:
            errors = _submit_and_record(engine.client, pending, datasets, regions, mask, store,
                                        counts, progress)
        finally:
            engine.__exit__(None, None, None)
        for error, n in errors.items():
            say(f"{n} task{'s' if n > 1 else ''} failed with {error}")
        counts["seconds"] = time.perf_counter() - start
        return counts


def _submit_and_record(client, pending, datasets, regions, mask, store, counts, progress):
    """Submit every pending task (after one clean reference per dataset and operator)
    and record each as it finishes; returns {error: count} of the failed ones."""
    from dask.distributed import as_completed

    needed = {t["dataset"] for t in pending}
    scattered = {name: client.scatter(volume, hash=False)
                 for name, volume, _ in datasets if name in needed}
    references = {}
    for t in pending:
        which = (t["dataset"], t["operator"], t["field"])
        if which not in references:
            references[which] = client.submit(clean_reference_safely, scattered[which[0]],
                                              which[1], regions, mask, 1, which[2], t["cut"],
                                              pure=False)
    futures = {}
    run_token = uuid.uuid4().hex[:8]  # two runs on one scheduler never share keys
    for t in pending:
        name = (f"noise-{t['dataset']}-{t['operator']}-{t['field']}-{t['level']}-"
                f"{t['seed']}-{run_token}")
        future = client.submit(run_task_safely, t, scattered[t["dataset"]],
                               references[(t["dataset"], t["operator"], t["field"])],
                               key=name)
        futures[future] = t
    errors = {}
    for future in as_completed(futures):
        task = futures.pop(future)
        try:
            row = future.result()
        except Exception as err:  # noqa: BLE001 - the worker died, or the like
            row = _failure(err)
        if "error" in row:  # recorded with its error; the others go on
            store.record(task, status="failed", error=row["error"])
            errors[row["error"]] = errors.get(row["error"], 0) + 1
            counts["failed"] += 1
            progress.tick(failed=True)
        else:
            store.record(row)
            counts["ran"] += 1
            progress.tick()
        future.release()
    return errors


# ---------------------------------------------------------------- the report


_STYLES = ["-", "--", ":", "-."]


def summarize(rows):
    """Mean, standard deviation, min and max over seeds per (dataset, operator, field,
    cut, mask, level)."""
    groups = {}
    for row in rows:
        key = (row["dataset"], row["operator"], row.get("field", "curvature"), row["cut"],
               row["mask"], row["level"])
        groups.setdefault(key, []).append(row)
    out = []
    for (dataset, operator, field, cut, mask, level), members in sorted(groups.items()):
        entry = {"dataset": dataset, "operator": operator, "field": field, "cut": cut,
                 "mask": mask, "level": level, "seeds": len(members)}
        for metric in ("similarity", "similarity_foreground", "region_ratio", "n_regions",
                       "largest_share", "seconds"):
            values = np.array([m.get(metric, np.nan) for m in members], dtype=float)
            entry.update({f"{metric}_mean": values.mean(), f"{metric}_std": values.std(),
                          f"{metric}_min": values.min(), f"{metric}_max": values.max()})
        out.append(entry)
    return out


def report(out_dir) -> list[Path]:
    """``tasks.csv`` (every row) and ``summary.csv`` in `out_dir`; for the paper's
    threshold cut ``fig5.png`` and ``fig5_foreground.png`` (similarity over the clean
    foreground), for the region-count cut ``fig5_regions.png``; for runs with
    ``--mask auto``, ``fig5_masked.png`` (segmented and scored on the foreground)."""
    out_dir = Path(out_dir)
    if not (out_dir / DB_NAME).exists():
        raise UsageError(f"{out_dir / DB_NAME}: no results to report (run first)")
    with _store(out_dir) as store:
        tasks_csv = store.export_csv(out_dir / "tasks.csv")
        rows = store.rows("done")
    if not rows:
        raise UsageError(f"{out_dir / DB_NAME}: no finished tasks to report")
    summary = summarize(rows)
    summary_csv = write_csv(out_dir / "summary.csv", summary)
    paths = [tasks_csv, summary_csv]
    masked = [s for s in summary if s["mask"] != "none" and s["cut"] == "threshold"]
    if masked:
        paths.append(_figure(masked, out_dir / "fig5_masked.png",
                             title="foreground only (mask auto), threshold held"))
    summary = [s for s in summary if s["mask"] == "none"]
    held = [s for s in summary if s["cut"] == "threshold"]
    if held:
        paths.append(_figure(held, out_dir / "fig5.png"))
        paths.append(_figure(held, out_dir / "fig5_foreground.png",
                             panels=[("similarity_foreground",
                                      "Huang-Dom similarity, foreground voxels only"),
                                     ("region_ratio", "region-number ratio min/max")]))
    defaults = [s for s in summary if s["cut"] == "defaults"]
    if defaults:
        paths.append(_figure(defaults, out_dir / "fig5_defaults.png",
                             panels=[("similarity", "Huang-Dom similarity, all voxels"),
                                     ("largest_share", "largest region's share")],
                             title="every default re-estimated on each volume",
                             by_field=True))
    recut = [s for s in summary if s["cut"] == "regions"]
    if recut:
        paths.append(_figure(recut, out_dir / "fig5_regions.png",
                             panels=[("similarity", "Huang-Dom similarity, all voxels"),
                                     ("similarity_foreground",
                                      "Huang-Dom similarity, foreground voxels only")],
                             title="each noisy result cut into the clean region count"))
    return paths


_PANELS = [("similarity", "Huang-Dom similarity to the clean result"),
           ("region_ratio", "region-number ratio min/max")]


def _figure(summary, path, panels=_PANELS, title="threshold of the clean result held fixed",
            by_field=False):
    """Fig. 5's layout: similarity and region ratio vs noise, a line per operator (or
    field) and dataset (colour = operator or field, style = dataset), mean over seeds
    with a min-max band. Levels sit at even spacing (the paper's axis also jumps in
    rate)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    levels = sorted({s["level"] for s in summary})
    position = {level: i for i, level in enumerate(levels)}
    datasets = sorted({s["dataset"] for s in summary}, key=lambda d: (
        DEFAULT_DATASETS.index(d) if d in DEFAULT_DATASETS else 99, d))
    fig = Figure(figsize=(13, 4.4), dpi=100, layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(1, 2)
    for ax, (metric, panel_title) in zip(axes, panels, strict=True):
        for d, dataset in enumerate(datasets):
            for series in sorted({(s["operator"], s["field"]) for s in summary}):
                line = [s for s in summary if s["dataset"] == dataset
                        and (s["operator"], s["field"]) == series]
                if not line:
                    continue
                x = [position[s["level"]] for s in line]
                operator, field = series
                color = (FIELD_COLOURS.get(field, "k") if by_field
                         else REGISTRY[operator].colour)
                name = field if by_field else REGISTRY[operator].label
                ax.plot(x, [s[f"{metric}_mean"] for s in line], _STYLES[d % len(_STYLES)],
                        color=color, marker="o", markersize=3, label=f"{name}, {dataset}")
                ax.fill_between(x, [s[f"{metric}_min"] for s in line],
                                [s[f"{metric}_max"] for s in line], color=color, alpha=0.12,
                                linewidth=0)
        ax.set_xticks(range(len(levels)), [f"{v:g}" for v in levels])
        ax.set_xlabel("noise sigma, % of the value range (uneven steps)")
        ax.set_ylabel(metric.replace("_", " "))
        ax.set_title(panel_title, fontsize=10)
        ax.grid(alpha=0.3)
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, fontsize=7, loc="outside right center")
    seeds = max(s["seeds"] for s in summary)
    fig.suptitle(f"Segmentation stability under noise, {title} (mean over up to {seeds} "
                 "seeds, band = min-max)", fontsize=11)
    return save_figure(fig, path)


# ---------------------------------------------------------------- command line


def _parser():
    p = argparse.ArgumentParser(prog="python -m pipelines.noise_stability",
                                description=__doc__.split("\n\n")[0])
    p.add_argument("--out", required=True, help="output folder (results.sqlite, CSV, figure)")
    p.add_argument("--datasets", nargs="+", default=list(DEFAULT_DATASETS),
                   metavar="NAME_OR_PATH")
    operators, shown = cli_choices()
    p.add_argument("--operators", nargs="+", default=list(DEFAULT_OPERATORS),
                   choices=operators, metavar=shown)
    p.add_argument("--levels", nargs="+", type=float, default=list(DEFAULT_LEVELS),
                   metavar="PERCENT", help="noise sigma in %% of the value range")
    p.add_argument("--seeds", type=int, default=DEFAULT_SEEDS, help="seeds per level")
    p.add_argument("--regions", type=int, default=DEFAULT_REGIONS,
                   help="regions of the clean segmentation that fix the threshold")
    p.add_argument("--cut", choices=CUTS, default="threshold",
                   help="threshold: hold the clean threshold (the paper); regions: cut "
                   "each noisy result into the clean region count; defaults: segment the "
                   "clean and each noisy volume with every default, as a user runs them")
    p.add_argument("--fields", nargs="+", default=["curvature"], choices=list(FIELDS),
                   help="with --cut defaults: the fields to segment (default curvature)")
    p.add_argument("--mask", choices=MASKS, default="none",
                   help="auto: segment and score only the clean volume's foreground (the "
                   "minimum plateau masked out when it covers over half the volume)")
    p.add_argument("--workers", type=int, help="LocalCluster workers (default: cores)")
    p.add_argument("--scheduler", metavar="ADDRESS", help="use an existing Dask scheduler")
    p.add_argument("--report", action="store_true", help="then write CSV and the figure")
    p.add_argument("--report-only", action="store_true", help="only write CSV and the figure")
    p.add_argument("-q", "--quiet", action="store_true")
    return p


def main(argv=None) -> int:
    args = _parser().parse_args(argv)

    def say(message):
        if not args.quiet:
            print(f"noise-stability: {message}", file=sys.stderr, flush=True)

    try:
        if args.seeds < 1 or args.regions < 1:
            raise UsageError("--seeds and --regions must be at least 1")
        if args.workers is not None and args.workers < 1:
            raise UsageError(f"--workers must be at least 1, got {args.workers}")
        bad = [v for v in args.levels if not np.isfinite(v) or v < 0]
        if bad:
            raise UsageError(f"--levels must be non-negative numbers, got {bad[0]}")
        if not args.report_only:
            operators = list(dict.fromkeys(normalize_operator(o) for o in args.operators))
            datasets = [load_dataset(spec) for spec in args.datasets]
            names = [d[0] for d in datasets]
            if len(set(names)) != len(names):
                raise UsageError(f"two datasets share a name: {names}")
            counts = run(datasets, args.out, operators=operators, levels=args.levels,
                         seeds=args.seeds, regions=args.regions, cut=args.cut,
                         mask=args.mask, scheduler=args.scheduler,
                         workers=args.workers, fields=args.fields, say=say)
            say(f"ran {counts['ran']} tasks ({counts['failed']} failed) in "
                f"{counts['seconds']:.1f} s; {counts['already_done']} were already done")
        if args.report or args.report_only:
            for path in report(args.out):
                print(path)
    except UsageError as err:
        print(f"noise-stability: error: {err}", file=sys.stderr)
        return 2
    except (OSError, sqlite3.Error) as err:
        print(f"noise-stability: error: {args.out}: cannot write the results "
              f"({getattr(err, 'strerror', None) or err})", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("noise-stability: interrupted; finished tasks are saved, rerun to continue",
              file=sys.stderr)
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
