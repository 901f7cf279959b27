"""Batch pipelines that reproduce the paper's evaluation: `python -m pipelines.<name>`.

- `pipelines.noise_stability`: stability of segmentations under value noise (Fig. 5),
  on dask.distributed, resumable through an SQLite results file.
- `pipelines.analytic`: curvature error on the six analytic functions (Figs. 2-3).
"""
