"""bfloat16 against fp32 inference on real scenes: the largest disparity difference and the change in
BadPix 0.07 / MSE x100, with the weights of a checkpoint (e.g. the Keras reference converted with
``lfbench convert-keras``, or the ``.hdf5`` itself).

    python benchmarks/bf16_accuracy.py --hci $LFBENCH_HCI_ROOT \
        --weights ../shared/data/reference/subfocal_keras_64/model.hdf5 --crop 128 --json bf16.json

Each scene is cropped to its central ``--crop`` px (0 = whole image) to keep the run short; scores use
the scene's ground truth on the crop with the benchmark's 15 px border left out. Both precisions run
the same fast path (lfbench_methods.subfocal.inference.infer); only the 3D aggregation changes precision.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np


def measure(net, scene, crop: int, border: int = 15) -> dict:
    """fp32 and bf16 predictions of one scene (central crop): differences and scores."""
    import torch
    from lfbench_methods.subfocal.inference import infer

    from lfbench.scoring.metrics import bad_pix, mse_x100
    from lfbench.scoring.prepare import border_mask

    views = scene.gray_views()  # (9, 9, H, W)
    gt = scene.gt_disparity()
    h, w = gt.shape
    c = min(crop or h, h, w)
    y0, x0 = (h - c) // 2, (w - c) // 2
    views = np.ascontiguousarray(views[:, :, y0:y0 + c, x0:x0 + c].reshape(81, c, c), dtype=np.float32)
    gt = gt[y0:y0 + c, x0:x0 + c]
    mask = border_mask(gt.shape, border)
    out = {"scene": scene.name, "crop": [y0, x0, c, c]}
    preds = {}
    for precision in ("fp32", "bf16"):
        t = time.perf_counter()
        preds[precision] = infer(net, torch.from_numpy(views), precision=precision).disparity[0].numpy()
        out[f"seconds_{precision}"] = time.perf_counter() - t
        out[f"badpix_0.07_{precision}"] = bad_pix(gt, preds[precision], 0.07, mask)
        out[f"mse_x100_{precision}"] = mse_x100(gt, preds[precision], mask)
    diff = np.abs(preds["bf16"] - preds["fp32"])
    out.update({"max_abs_diff_px": float(diff.max()), "mean_abs_diff_px": float(diff.mean()),
                "max_abs_diff_px_scored": float(diff[mask].max()),
                "badpix_0.07_change": out["badpix_0.07_bf16"] - out["badpix_0.07_fp32"],
                "mse_x100_change": out["mse_x100_bf16"] - out["mse_x100_fp32"]})
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--hci", type=Path, required=True, help="HCI data root (ROOT/<category>/<scene>/)")
    p.add_argument("--weights", type=Path, required=True, help="checkpoint .pt or the authors' Keras .hdf5")
    p.add_argument("--scenes", nargs="+", default=["backgammon", "antinous"])
    p.add_argument("--crop", type=int, default=128, help="central crop in px (0 = whole scene)")
    p.add_argument("--threads", type=int, default=0)
    p.add_argument("--json", type=Path)
    args = p.parse_args(argv)

    import os

    import torch

    from lfbench.data.hci import HCIDataset

    torch.set_num_threads(args.threads or os.cpu_count() or 1)
    if args.weights.suffix in (".h5", ".hdf5"):
        from lfbench_methods.subfocal.keras_import import load_keras_checkpoint

        net = load_keras_checkpoint(args.weights)
    else:
        from lfbench_methods.subfocal.keras_import import build_from_checkpoint

        net = build_from_checkpoint(args.weights)
    bench = HCIDataset.open(args.hci)
    records = []
    for scene in bench.select(args.scenes):
        r = measure(net.eval(), scene, args.crop)
        r["weights"] = str(args.weights)
        records.append(r)
        print(json.dumps(r), flush=True)
    if args.json:
        from lfbench.utils.atomic import write_text

        write_text(args.json, json.dumps(records, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
