"""Runs: methods run on scenes and scored into a folder (runner), their records (results), golden
regression checks (regress), the offline demo (demo) and speed/memory benchmarks (bench)."""
