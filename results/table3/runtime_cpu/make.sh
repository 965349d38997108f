#!/usr/bin/env bash
# The runtime column of SubFocal's Table III measured as the paper measured it (one 9x9x256x256 light field,
# mean of timed runs after a warm-up, the paper's UrbanLF-Syn grid [-0.5, 1.6] at 0.1 px, width 150), on the
# CPU of this machine. REPEAT defaults to 3, not the paper's 50: one run takes minutes on a 2-core CPU.
# Usage: bash results/table3/runtime_cpu/make.sh   (writes runtime.json and runtime.md beside this file)
set -euo pipefail
HERE=$(cd "$(dirname "$0")" && pwd)
REPEAT=${REPEAT:-3}
lfbench bench inference --size 256 --repeat "$REPEAT" --mean --precision fp32 --interval 0.1 --d-min -0.5 \
    --d-max 1.6 --width 150 --no-peak --device cpu --json "$HERE/runtime.json" --table "$HERE/runtime.md"
