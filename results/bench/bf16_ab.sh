#!/usr/bin/env bash
# Before/after of benchmarks/bf16_floor.py, interleaved under the same load: the code of commit BEFORE (a
# git archive of lfbench/ and methods/ in a temporary folder, first on PYTHONPATH) against the working tree,
# ROUNDS times, pinned to one core (CORE, default 1), one torch thread.
#
#   bash results/bench/bf16_ab.sh BEFORE SIZE ROUNDS OUT_PREFIX [bf16_floor.py options]
#   bash results/bench/bf16_ab.sh b31c2f3 128 3 results/bench/bf16_floor_128_ab
#
# Writes OUT_PREFIX.json (the records, each with "code": before or after, and "round") and prints one line
# per run. The BEFORE tree gets this tree's methods/subfocal/inference.py phase clocks only when it has
# none (timings["cpu"]); nothing it computes changes.
set -euo pipefail
before=$1 size=$2 rounds=$3 out=$4
shift 4
root=$(git rev-parse --show-toplevel)
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
git -C "$root" archive "$before" lfbench methods | tar -x -C "$tmp"
ln -s methods "$tmp/lfbench_methods"
if ! grep -q 'cpu=cpu' "$tmp/methods/subfocal/inference.py"; then
    python - "$tmp/methods/subfocal/inference.py" <<'EOF'
import re, sys
path = sys.argv[1]
s = open(path).read()
s = s.replace("    clock = time.perf_counter()\n", "    clock, cpu_clock = time.perf_counter(), time.process_time()\n", 1)
s = s.replace('    times = {"features_s": time.perf_counter() - clock}\n    clock = time.perf_counter()\n',
              '    times = {"features_s": time.perf_counter() - clock}\n    cpu = {"features_s": time.process_time() - cpu_clock}\n'
              '    clock, cpu_clock = time.perf_counter(), time.process_time()\n')
s = s.replace('    times["attention_s"] = time.perf_counter() - clock\n    clock = time.perf_counter()\n',
              '    times["attention_s"] = time.perf_counter() - clock\n    cpu["attention_s"] = time.process_time() - cpu_clock\n'
              '    clock, cpu_clock = time.perf_counter(), time.process_time()\n')
s = s.replace('    times["aggregation_s"] = time.perf_counter() - clock\n    if timings is not None:\n        timings.update(times, ',
              '    times["aggregation_s"] = time.perf_counter() - clock\n    cpu["aggregation_s"] = time.process_time() - cpu_clock\n'
              '    if timings is not None:\n        timings.update(times, cpu=cpu, ')
assert s.count("cpu_clock") == 6, "unexpected inference.py: cannot add the CPU phase clocks"
open(path, "w").write(s)
EOF
fi
runs=()
for round in $(seq "$rounds"); do
    for code in before after; do
        path=$([ "$code" = before ] && echo "$tmp" || echo "$root")
        json="$tmp/$code-$round.json"
        (cd "$tmp" && PYTHONPATH="$path" taskset -c "${CORE:-1}" python "$root/benchmarks/bf16_floor.py" --size "$size" \
            --repeat 1 --threads 1 --json "$json" "$@" | grep -E '^(bf16|fp32): ' | sed "s/^/$code round $round: /")
        runs+=("$code:$round:$json")
    done
done
python - "$out.json" "${runs[@]}" <<'EOF'
import json, sys
records = []
for run in sys.argv[2:]:
    code, rnd, path = run.split(":", 2)
    for r in json.load(open(path)):
        records.append({"code": code, "round": int(rnd), **r})
with open(sys.argv[1], "w") as f:
    json.dump(records, f, indent=2)
    f.write("\n")
EOF
