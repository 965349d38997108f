#!/usr/bin/env bash
# HCI scoring speed before and after the dataset seam (issue 30, Measure: "unchanged for HCI").
# `lfbench bench metrics` (12 generated 512x512 HCI scenes x 20 predictions, the 5 general metrics, one torch
# thread, best of 3 per run) of the commit before the seam (f7a4640^, installed into a temporary venv) and of
# the lfbench on PATH (this checkout, installed as the README says), interleaved ROUNDS times in one run so both
# see the same load; then summarize.py writes summary.md. Usage, from the repository root, venv active:
#   bash results/bench/scoring_hci_before_after/make.sh [ROUNDS]      # ~3 min with 6 rounds
set -euo pipefail
ROUNDS=${1:-6}
HERE=$(cd "$(dirname "$0")" && pwd)
ROOT=$(git -C "$HERE" rev-parse --show-toplevel)
BEFORE=f7a4640^
TMP=$(mktemp -d)
cleanup() { git -C "$ROOT" worktree remove --force "$TMP/src" 2>/dev/null || true; rm -rf "$TMP"; }
trap cleanup EXIT
git -C "$ROOT" worktree add --quiet --detach "$TMP/src" "$BEFORE"
python3 -m venv "$TMP/venv"
"$TMP/venv/bin/pip" install -q -c "$ROOT/constraints/cpu.txt" -e "$TMP/src"
mkdir -p "$TMP/out"
for r in $(seq 1 "$ROUNDS"); do
  (cd "$TMP" && "$TMP/venv/bin/lfbench" bench metrics --methods 20 --threads 1 --repeat 3 --json "$TMP/out/before_$r.json" >/dev/null)
  (cd "$TMP" && lfbench bench metrics --methods 20 --threads 1 --repeat 3 --json "$TMP/out/after_$r.json" >/dev/null)
done
python "$HERE/summarize.py" "$TMP/out" "$(git -C "$ROOT" rev-parse --short "$BEFORE")" \
    "$(git -C "$ROOT" rev-parse --short HEAD)" > "$HERE/summary.md"  # (re-run on the copied records: python summarize.py . BEFORE AFTER)
cp "$TMP"/out/*.json "$HERE/"
cat "$HERE/summary.md"
