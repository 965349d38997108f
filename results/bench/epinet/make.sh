#!/bin/sh
# EPINET's CPU fp32 inference at 9x9x256x256 against its convolution floor and a straightforward NCHW port
# (benchmarks/epinet_floor.py); writes floor_256.json here. Run from the repository root.
set -e
python benchmarks/epinet_floor.py --size 256 --threads 2 --repeat 2 --json results/bench/epinet/floor_256.json
