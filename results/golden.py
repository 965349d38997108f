"""Recompute the deterministic runs behind results/golden.json.

    python results/golden.py --out OUT [--hci ../shared/data/hci]
    lfbench regress results/golden.json OUT/results.json            # the CI check (nox -s regress)
    python results/golden.py --out OUT --hci ../shared/data/hci --update results/golden.json   # refresh

Tolerances (TOLERANCES, absolute, in each metric's unit): a stored map must not move at all; a
network on CPU may flip a few pixels across BadPix thresholds between CPU types (one pixel of a
66x66 scored crop is 0.023 %); the plane sweep is bit-identical between runs.

Runs: the training-free plane sweep and the shipped SubFocal checkpoint (as the variant its weights
have, e.g. subfocal:width=16; lfattnet when a checkpoint is shipped for it) on a synthetic mini benchmark
(seed 0, 96x96, 3 scenes), and, when the HCI data is given, the published SubFocal maps on the
real scenes that have them.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import torch

from lfbench.data.hci import HCIDataset
from lfbench.data.synth import write_benchmark
from lfbench.method.registry import REGISTRY, create, offline_variants
from lfbench.runs.folder import evaluate_to_folder
from lfbench.runs.regress import make_golden

SYNTH = {"seed": 0, "size": 96, "scenes": 3}
SYNTH_METHODS = ("planesweep", "subfocal", "lfattnet")
TOLERANCES = {"published*/*": 1e-6, "subfocal*/*": 0.25, "lfattnet*/*": 0.25, "*": 0.05}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--hci", type=Path, default=None, help="HCI data root (published maps are looked up beside it)")
    ap.add_argument("--update", type=Path, default=None, metavar="GOLDEN",
                    help="also write the results as golden records with TOLERANCES")
    args = ap.parse_args(argv)
    torch.manual_seed(0)
    data = args.out / "data"
    if not data.exists():
        write_benchmark(data, **SYNTH)
    scenes = list(HCIDataset.open(data))
    methods = []
    for name in SYNTH_METHODS:
        if name not in REGISTRY.names():
            continue
        for params in offline_variants(name):  # e.g. subfocal:width=16 (shipped weights)
            method = create(name, **params)
            if method.available_for(scenes[0]) is None:
                methods.append(method)
    more = []
    if args.hci is not None:
        published = args.hci.parent / "published" / "subfocal"
        if published.is_dir():
            real = [s for s in HCIDataset.open(args.hci) if s.has_gt()]
            more.append(([create("published", path=published)], real))
    meta = {"golden_setup": {"synthetic": SYNTH, "hci": str(args.hci) if args.hci else None}}
    results = evaluate_to_folder(methods, scenes, args.out, more=more, writers=(), meta=meta, progress=False)
    print(f"{len(results.records)} records from {', '.join(results.methods)} -> {args.out / 'results.json'}")
    if args.update is not None:
        n = make_golden(results, TOLERANCES, args.update)
        print(f"wrote {n} golden records to {args.update}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
