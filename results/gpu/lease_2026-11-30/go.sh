#!/bin/bash
# Device driver (not committed): GPU continuation of the shipped model, time-boxed by SIGINT + cut-on-resume,
# then benchmarks/gpu_check.py. Env: CFG (config), L1_END, UAFL_END, END (seconds since start), OUT.
set -u
T0=$(date +%s)
el() { echo $(( $(date +%s) - T0 )); }
export PYTHONUNBUFFERED=1
CFG=${CFG:-configs/subfocal_gpu_small_continue.toml}
L1_END=${L1_END:-270}; UAFL_END=${UAFL_END:-350}; END=${END:-535}
RUN=${RUN:-/tmp/gpurun}
PY=${PY:-python3}
exec > >(tee -a "$OUT/driver.log") 2>&1
echo "start $(date -u)"; nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv 2>&1 | tail -2
if [ -z "${SKIP_INSTALL:-}" ]; then
  $PY -m pip install -q --no-deps --no-build-isolation -e . 2>&1 | tail -2
fi
$PY -c "import torch, lfbench; print('torch', torch.__version__, 'cuda', torch.cuda.is_available())"
export LFBENCH_HCI_ROOT=${LFBENCH_HCI_ROOT:-$PWD/.devrun/hci}
cp "$CFG" "$OUT/config_planned.toml"

cut() {  # cut stage $1's steps (1-based) to $2 in $CFG
  $PY - "$CFG" "$1" "$2" <<'PY'
import re, sys
path, stage, steps = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
text = open(path).read()
parts = re.split(r"(?m)^(?=\[\[stages\]\])", text)
parts[stage] = re.sub(r"(?m)^steps = \d+", f"steps = {steps}", parts[stage], count=1)
open(path, "w").write("".join(parts))
PY
}
leg() {  # leg N DEADLINE: run/resume training until it ends or DEADLINE; echoes "stage step" when stopped
  local n=$1 deadline=$2
  $PY -m lfbench train "$CFG" --out "$RUN" --no-progress > "$OUT/train$n.log" 2>&1 &
  local pid=$!
  while kill -0 $pid 2>/dev/null && [ "$(el)" -lt "$deadline" ]; do sleep 1; done
  kill -INT $pid 2>/dev/null
  wait $pid; local rc=$?
  echo "leg $n rc=$rc at $(el) s: $(tail -1 "$OUT/train$n.log")" >&2
  grep -o "stopped at stage [0-9]* step [0-9]*" "$OUT/train$n.log" | tail -1 | awk '{print $4, $6}'
}
s=$(leg 1 "$L1_END")
if [ -n "$s" ]; then
  set -- $s; cut "$1" "$2"; echo "cut stage $1 at step $2"
  s=$(leg 2 "$UAFL_END")
  if [ -n "$s" ]; then
    set -- $s; cut "$1" "$2"; echo "cut stage $1 at step $2"
    leg 3 $((END)) >/dev/null
  fi
fi
cp "$CFG" "$OUT/config_ran.toml"
tar czf "$OUT/run.tgz" -C "$RUN" --exclude=./data --exclude=./checkpoint.pt . 2>&1 | tail -1
ls -la "$RUN" | head -20
left=$(( END - $(el) ))
echo "gpu_check with $left s left"
if [ "$left" -gt 30 ] && [ -z "${SKIP_CHECK:-}" ]; then
  timeout -s INT "$left" $PY benchmarks/gpu_check.py --json "$OUT/gpu_check.json" ${CHECK_ARGS:-}
  echo "gpu_check rc=$? at $(el) s"
fi
echo "end at $(el) s"
