"""The evaluation report (`make eval`): turns the records of the Rust `conesight-eval` run into
tables and plots against the paper's figures, `docs/results.md` and `docs/results.json`.

Modules:
- `records`: reading `build/eval/*.jsonl` and `meta.json`.
- `metrics`: range bands, 3D error, perturbation variance, PnP variants, the CI check subset.
- `opencv_pnp`: OpenCV's solvePnP / solvePnPRansac on the same keypoints.
- `plots`: the PNGs (matplotlib).
- `paper`: the paper's figures the report compares against.
- `markdown`: `docs/results.md`.
- `__main__`: the CLI (`python -m conesight_train.report --help`).
"""
