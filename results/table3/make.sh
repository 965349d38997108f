#!/usr/bin/env bash
# SubFocal's Table III beside lfbench's rows on SYNTHETIC scenes in the UrbanLF-Syn layout (not UrbanLF-Syn:
# the numbers are not comparable to the paper's; see README.md). Usage: bash results/table3/make.sh PAPER_DIR
# (PAPER_DIR: the folder of the paper's CSV files, e.g. ../shared/data/paper). Writes results/table3/run
# (results.json/csv, tables) and results/table3/report (the side-by-side table_table3_paper.*, not committed:
# it holds the paper's numbers from PAPER_DIR).
set -euo pipefail
PAPER=${1:?usage: make.sh PAPER_DIR (the paper folder holding table3_urbanlf.csv)}
HERE=$(cd "$(dirname "$0")" && pwd)
DATA=$(mktemp -d)
trap 'rm -rf "$DATA"' EXIT
SIZE=${SIZE:-160x120}  # small, for a 2-core CPU (the real samples are 640x480)
# the synthetic scenes' disparities lie in UrbanLF-Syn's released [-0.47, 1.55] px: the sweep searches the dataset's
# grid ([-0.5, 1.6] at 0.1 px, the paper's)
rm -rf "$HERE/run" "$HERE/report"
lfbench synth --layout urbanlf-syn --size "$SIZE" --numbers 11,27,34,50,54,68,69,70 --seed 0 --out "$DATA"
# subfocal:width=16: the shipped checkpoint (results/shipped_model: trained on lfbench's synthetic HCI-layout
# scenes and antinous; it searches its own [-4, 4] at 0.5 px on any dataset)
lfbench evaluate --data "$DATA" --method subfocal:width=16 --method planesweep --method gt --method constant \
    --out "$HERE/run" --no-progress
lfbench report "$HERE/run" --out "$HERE/report" --paper "$PAPER" --format md,csv
python "$HERE/paired.py" "$HERE/run" subfocal planesweep
