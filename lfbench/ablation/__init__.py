"""Ablations: ``lfbench ablate SPEC.toml`` trains a grid of SubFocal variants with a stated budget,
scores each on stated scenes and writes the paper's tables (IV, V, the beta sweep, I/II) with the
paper's numbers beside ours.

Modules: spec (the TOML spec and its cells), toml_text (writing a cell's training config), cell (one
cell: train, evaluate, time, marker), runner (all cells, resumable, in parallel processes), report
(tables) and plots (figures).
"""
