"""Ablations: ``lfbench ablate SPEC.toml`` trains a grid of variants of a registered trainable network
(SubFocal by default; the axes are its parameters) with a stated budget, scores each on stated scenes
and writes the tables (for SubFocal the paper's IV, V, the beta sweep, I/II, with the paper's numbers
beside ours).

Modules: spec (the TOML spec, its declared keys and its cells), reference (the spec's reference docs), cell (one
cell: train, evaluate, time, marker), runner (all cells, resumable, in parallel processes), report
(tables), significance (seeds: intervals and paired tests), baselines (does every cell beat the
spec's [[methods]]?) and plots (figures).
"""
