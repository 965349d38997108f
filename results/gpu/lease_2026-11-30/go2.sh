#!/bin/bash
set -u
export PYTHONUNBUFFERED=1
T0=$(date +%s); el() { echo $(( $(date +%s) - T0 )); }
exec > >(tee -a "$OUT/driver2.log") 2>&1
python3 -m pip install -q --no-deps --no-build-isolation -e . 2>&1 | tail -2
echo "installed at $(el) s"
timeout -s KILL 50 python3 benchmarks/gpu_check.py --only gpu_vs_cpu tiled_vs_whole phase --json "$OUT/gpu_check.json"
echo "gpu_check rc=$? at $(el) s"
timeout -s KILL $(( 170 - $(el) )) python3 .devrun/prof.py cuda "$OUT" $(( 150 - $(el) ))
echo "prof rc=$? at $(el) s"
