#!/usr/bin/env bash
# Regenerates the shipped SubFocal model (methods/weights/subfocal_small.pt) and its record here:
# training/ (the config, per-step log and summary of `lfbench train`) and evaluation/ (scores on the
# real HCI scenes beside the published SubFocal maps and the plane sweep, with the uncertainty rating).
# About 40 min on 2 free CPU cores (training ~36 min, evaluation ~2 min).
#   LFBENCH_HCI_ROOT=../shared/data/hci bash results/shipped_model/make.sh
set -euo pipefail
cd "$(dirname "$0")/../.."
: "${LFBENCH_HCI_ROOT:?set LFBENCH_HCI_ROOT to the HCI data root (e.g. ../shared/data/hci)}"
here=results/shipped_model
run=runs/subfocal_cpu_small

lfbench train configs/subfocal_cpu_small.toml --out "$run"
cp "$run/final.pt" methods/weights/subfocal_small.pt
mkdir -p "$here/training"
cp "$run/config.toml" "$run/metrics.jsonl" "$run/summary.json" "$run/command.txt" "$here/training/"

# antinous was a training scene: it is scored too, but only backgammon is unseen.
rm -rf "$here/evaluation"
lfbench evaluate --data "$LFBENCH_HCI_ROOT" --method subfocal:width=16 \
    --method "published:path=$LFBENCH_HCI_ROOT/../published/subfocal" --method planesweep \
    --out "$here/evaluation" --uncertainty --ci --no-progress
