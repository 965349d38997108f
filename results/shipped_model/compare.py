"""Paired comparison of the shipped SubFocal with the training-free plane sweep, the zero map and the model it
replaced on the held-out synthetic scenes (evaluation_synthetic/): per scene, and a paired t-test over the
scenes; and a power-law projection (validation BadPix = a * patches^-b, fitted to the three runs' validation
curves, in training patches seen since the runs differ in batch size) of the training the model would need to
reach given BadPix levels on backgammon from where it is now (evaluation/).

    python results/shipped_model/compare.py   # writes results/shipped_model/comparison.{md,tex,csv} (make.sh runs it)
"""

from __future__ import annotations

import json
import statistics
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd

from lfbench.ablation.significance import paired_t
from lfbench.reports.tables import write_table
from lfbench.results import Results

HERE = Path(__file__).resolve().parent
OURS = "subfocal:width=16"
PREVIOUS = "subfocal:weights=runs/subfocal_cpu_small_continue/best.pt"  # the model this one replaced (run 2)
BASELINES = ("planesweep", "constant", PREVIOUS)
METRICS = ("badpix_0.07", "mse_x100")  # lower is better for both
# (record folder, the weights it hands on): run 2 starts from run 1's final.pt, run 3 from run 2's best.pt;
# run 3's best.pt ships
RUNS = (("training", "final.pt"), ("continuation", "best.pt"), ("gpu_continuation", "best.pt"))
TARGETS = {"issue 11's fallback bar": 12.0, "the plane sweep (interval 0.25)": None}


def run_record(folder: str) -> dict:
    """One run's batch size, steps, validation points (global step, BadPix %) and median training steps/s."""
    record = HERE / folder
    config = tomllib.loads((record / "config.toml").read_text(encoding="utf-8"))
    entries = [json.loads(line) for line in (record / "metrics.jsonl").read_text(encoding="utf-8").splitlines()]
    # a dict: a stage cut on resume logged its last validation twice
    validation = {e["global_step"]: e["badpix"] for e in entries if e["event"] == "validation"}
    rates = [e["steps_per_s"] for e in entries if e["event"] == "train"]
    steps = json.loads((record / "summary.json").read_text(encoding="utf-8"))["steps"]
    return {"batch": config["training"]["batch_size"], "device": config["training"].get("device", "auto"),
            "steps": steps, "validation": sorted(validation.items()), "steps_per_s": statistics.median(rates)}


def validation_curve() -> tuple[np.ndarray, np.ndarray, int]:
    """(patches seen, pooled validation BadPix 0.07 %) of all runs, one point per validation, and the patches
    seen by the shipped weights. Each run counts from the weights it started from: the final.pt or the best.pt
    (lowest validation BadPix, the first on a tie) of the run before."""
    patches, badpix, offset = [], [], 0
    for folder, hands_on in RUNS:
        run = run_record(folder)
        for step, value in run["validation"]:
            patches.append(offset + step * run["batch"])
            badpix.append(value)
        step = run["steps"] if hands_on == "final.pt" else min(run["validation"], key=lambda sv: sv[1])[0]
        offset += step * run["batch"]
    return np.asarray(patches, dtype=np.float64), np.asarray(badpix, dtype=np.float64), offset


def projection() -> pd.DataFrame:
    """Training to each target on backgammon, from the shipped model's score there, along the validation slope;
    in patches, and in hours at the measured rates of the GPU run and of the 2-core CPU run."""
    patches, badpix, done = validation_curve()
    slope, _ = np.polyfit(np.log(patches), np.log(badpix), 1)
    r2 = float(np.corrcoef(np.log(patches), np.log(badpix))[0, 1] ** 2)
    evaluation = Results.read(HERE / "evaluation")
    score = {(r.method, r.scene, r.metric): r.value for r in evaluation.records}
    now = score[OURS, "backgammon", "badpix_0.07"]
    rate = {}  # patches per second
    for folder, _ in RUNS:
        run = run_record(folder)
        rate[run["device"]] = run["steps_per_s"] * run["batch"]
    rows = []
    for label, target in TARGETS.items():
        target = target if target is not None else score["planesweep", "backgammon", "badpix_0.07"]
        total = done * (now / target) ** (1.0 / -slope)
        rows.append({"target on backgammon": f"{label}: BadPix 0.07 = {target:.2f} %", "fitted b": -slope,
                     "R^2 (log-log)": r2, "validations fitted": len(patches), "patches so far": done,
                     "backgammon now (%)": now, "total patches": int(round(total, -3)),
                     "GPU hours more (H200)": max(0.0, total - done) / rate["cuda"] / 3600,
                     "CPU hours more (2 cores)": max(0.0, total - done) / rate["cpu"] / 3600})
    return pd.DataFrame(rows).set_index("target on backgammon")


def main() -> None:
    results = Results.read(HERE / "evaluation_synthetic")
    value = {(r.method, r.scene, r.metric): r.value for r in results.records}
    scenes = sorted({r.scene for r in results.records})
    rows = []
    for base in BASELINES:
        for metric in METRICS:
            ours = [value[OURS, s, metric] for s in scenes]
            theirs = [value[base, s, metric] for s in scenes]
            test = paired_t(ours, theirs)
            pairs = list(zip(scenes, ours, theirs, strict=True))
            rows.append({"baseline": base, "metric": metric,
                         **{f"{s}: shipped / baseline": f"{o:.3f} / {b:.3f}" for s, o, b in pairs},
                         "shipped better on": f"{sum(b > o for _, o, b in pairs)} of {len(scenes)}",
                         "mean difference": test["mean_diff"], "95 % CI low": test["low"], "95 % CI high": test["high"],
                         "p (two-sided)": f"{test['p']:.3g}"})
    caption = [f"The shipped SubFocal ({OURS}) against its baselines on {len(scenes)} held-out synthetic scenes "
               "(evaluation_synthetic/: seed 1000, never used in training or validation); produced by "
               "`python results/shipped_model/compare.py`.",
               "mean difference = baseline minus shipped (positive: the shipped model is better), with its 95 % "
               "t-interval; paired t-test over the scenes."]
    write_table(pd.DataFrame(rows).set_index(["baseline", "metric"]), HERE, "comparison", caption)
    write_table(projection(), HERE, "projection", [
        "Training the shipped model would need on backgammon if it kept the slope of its validation curve "
        "(BadPix = a * patches^-b fitted to the validations in training/, continuation/ and gpu_continuation/ "
        "metrics.jsonl; patches = steps x batch); hours at each run's median measured rate; produced by "
        "`python results/shipped_model/compare.py`. An extrapolation: learning curves usually flatten."])


if __name__ == "__main__":
    main()
