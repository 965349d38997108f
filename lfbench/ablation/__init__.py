"""Ablations: ``lfbench ablate SPEC.toml`` trains a grid of variants of a registered trainable network
(SubFocal by default; the axes are its parameters) with a stated budget, scores each on stated scenes
and writes the tables (beside the reference of its network, lfbench.reports.reference: for SubFocal
its paper's IV, V, the beta sweep, I/II).

Modules: spec (the TOML spec, its declared keys and its cells), reference (docs/ablation-spec.md), cell (one
cell: train, evaluate with its maps, time, marker), runner (all cells, resumable), executor (where cells run:
the --executor registry, this process or worker processes), jobs (cells as submitit / SLURM jobs), scheduler
(bounded sbatch / squeue calls), facts (what each cell is: variant, seed, [model] values, loss, beta),
significance (seeds: intervals and paired tests), baselines (does every cell beat the spec's [[methods]]?),
plots (figures) and report (the ablation's output writers: tables, figures, the site, beside the reference of
the spec's network).
"""
