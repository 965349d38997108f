#!/usr/bin/env bash
# Table IV without training: the plane sweep (methods/planesweep.py) at disparity intervals 1 / 0.5 / 0.25 / 0.1
# x nearest / bilinear / phase (and bilinear without its sub-pixel fit) on backgammon, antinous and 4 synthetic
# scenes; writes interval_sweep.{md,tex,csv}, figures/interval_sweep.png and results.json here (the full run stays in
# runs/planesweep_table4; finished methods are not re-run, so an interrupted run continues).
# About 25 min on 2 free cores (1 thread): ~1-10 s per synthetic scene, 15-90 s per 512x512 scene per method.
#   LFBENCH_HCI_ROOT=../shared/data/hci bash results/planesweep_table4/make.sh
set -euo pipefail
cd "$(dirname "$0")/../.."
: "${LFBENCH_HCI_ROOT:?set LFBENCH_HCI_ROOT to the HCI data root (e.g. ../shared/data/hci)}"
here=results/planesweep_table4
run=runs/planesweep_table4

nice -n 19 lfbench ablate ablations/planesweep_table4.toml --out "$run" --no-progress
python -m lfbench.reports.sweep_table "$run" "$here" \
    --caption "Table IV without training: plane sweep (lfbench planesweep, star views, occlusion subsets, cross aggregation)" \
    --caption "real scenes at low resolution (512x512 ground truth, 15 px border); synthetic: mean of 4 scenes (128 px, seed 1000)" \
    --caption "time per scene: wall seconds of one prediction on this machine, 1 thread (shared machine: compare within a column)"
cp "$run/results.json" "$here/results.json"
