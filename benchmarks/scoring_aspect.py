"""Scoring speed on a 640x480 UrbanLF-Syn scene beside a 512x512 HCI scene (issue 30, Measure).

    python benchmarks/scoring_aspect.py [--repeat 5] [--json OUT.json]      # ~20 s on 2 cores

Writes one scene of each layout into a temporary folder (UrbanLF-Syn: 81 flat 640x480 views, a smooth random
5_5_disparity.npy; HCI: parameters.cfg and gt_disp_lowres.pfm), then times ``score_predictions`` of 5
predictions (ground truth plus noise of growing size) under each dataset's protocol (HCI: its 5 general
metrics; UrbanLF-Syn: BadPix 0.01 / 0.03 / 0.07, MSE x100), best of ``--repeat``, on one thread. Reading the
ground truth is part of the time, as in ``lfbench bench metrics``. Speed is measured here, never in the tests.
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402
from PIL import Image  # noqa: E402

from lfbench.data.hci import HCIDataset, HCIScene  # noqa: E402
from lfbench.data.urbanlf import UrbanLFScene, UrbanLFSyn, gt_name, view_name  # noqa: E402
from lfbench.runs.bench import _write_synthetic_scene  # noqa: E402
from lfbench.scoring.metrics import get_metric  # noqa: E402
from lfbench.scoring.rules import ScoringRules  # noqa: E402
from lfbench.scoring.score import score_predictions  # noqa: E402


def _urbanlf_scene(folder: Path, seed: int) -> np.ndarray:
    folder.mkdir(parents=True)
    blank = Image.new("RGB", (640, 480), (128, 128, 128))
    for r in range(1, 10):
        for c in range(1, 10):
            blank.save(folder / view_name(r, c), compress_level=1)
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:480, 0:640] / 480
    gt = (0.5 + np.sin(2 * np.pi * (x * rng.uniform(0.5, 2))) * np.cos(2 * np.pi * y)).astype(np.float32)
    np.save(folder / gt_name(), gt)
    return gt


def _time(scene, gt: np.ndarray, dataset, repeat: int) -> tuple[float, float]:
    """Best wall-clock and best CPU seconds of scoring 5 predictions on a freshly opened scene (its reference
    made anew each time)."""
    rules = ScoringRules.of_protocol(dataset.protocol)
    metrics = [get_metric(m) for m in dataset.protocol.metrics]
    rng = np.random.default_rng(0)
    preds = [((gt + rng.normal(0, s, gt.shape)).astype(np.float32), None, f"m{i}")
             for i, s in enumerate((0.005, 0.01, 0.03, 0.1, 0.3))]
    best, cpu = float("inf"), float("inf")
    for _ in range(repeat):
        fresh = type(scene)(scene.path, category=scene.category)
        start, start_cpu = time.perf_counter(), time.process_time()
        score_predictions(fresh, preds, metrics, rules)
        best = min(best, time.perf_counter() - start)
        cpu = min(cpu, time.process_time() - start_cpu)
    return best, cpu


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--repeat", type=int, default=5)
    p.add_argument("--json", type=Path)
    args = p.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        hci_gt = _write_synthetic_scene(Path(tmp) / "hci" / "scene", 512, 0)
        hci = HCIScene(Path(tmp) / "hci" / "scene", category="synthetic")
        urban_gt = _urbanlf_scene(Path(tmp) / "urban" / "Image1", 0)
        urban = UrbanLFScene(Path(tmp) / "urban" / "Image1", category="val")
        (hci_s, hci_cpu), (urban_s, urban_cpu) = (_time(hci, hci_gt, HCIDataset, args.repeat),
                                                  _time(urban, urban_gt, UrbanLFSyn, args.repeat))
        out = {"hci_512x512_s": hci_s, "urbanlf_640x480_s": urban_s, "predictions": 5, "repeat": args.repeat,
               "cpu_seconds": {"hci_512x512": hci_cpu, "urbanlf_640x480": urban_cpu}}
    out["per_prediction_ms"] = {k.removesuffix("_s"): 1000 * v / 5 for k, v in out.items() if k.endswith("_s")}
    print(json.dumps(out, indent=1))
    if args.json:
        args.json.write_text(json.dumps(out, indent=1) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
