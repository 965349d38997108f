"""Generate synthetic light fields with exact ground truth (no dataset needed), in the HCI layout or
UrbanLF-Syn's.

--layout hci (default): DIR/<category>/synth_<seed>_<i>/ for i = 0..K-1: input_Cam000..png,
parameters.cfg, gt_disp_lowres.pfm, gt_depth_lowres.pfm and evaluation masks (<mask>_lowres.png).
--layout urbanlf-syn: DIR/<category, default val>/Image<i>/ for i = 1..K (or i in --numbers): 9x9 views u_v.png
of WxH px (default 640x480), 5_5_disparity.npy and 5_5_depth.npy, disparities within UrbanLF-Syn's released
[-0.47, 1.55] px. --disparity-range LOW HIGH maps a scene's disparities into [LOW, HIGH] px (the same layout at
other depths; hci default: the generator's own, about [-2.1, 2.3]). The same seed, size, angular resolution
and range always give the same files. An existing scene folder is an error unless --force. DIR gets a file
SYNTHETIC, by which every table scored on DIR says that its data is synthetic (lfbench.data.provenance).
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path

from lfbench.cli.argtypes import add_flag
from lfbench.utils.flags import MAX_JOBS, SCENE_COUNT, SEED, section_flags
from lfbench.utils.options import option

HELP = "generate synthetic scenes (HCI or UrbanLF-Syn layout) with exact ground truth"


@dataclass(frozen=True, kw_only=True)
class SynthWorkers:
    """``lfbench synth --workers``, declared once."""

    workers: int | None = option(None, help="scenes generated at a time in separate processes (default: the "
                                 "available cores)", low=1, high=MAX_JOBS, metavar="N")


WORKERS = section_flags(SynthWorkers)["workers"]


def add_arguments(p: argparse.ArgumentParser) -> None:
    from lfbench.data.synth import ANGULAR

    p.add_argument("--out", required=True, type=Path, metavar="DIR", help="data root to write into")
    add_flag(p, SEED)
    p.add_argument("--layout", choices=("hci", "urbanlf-syn"), default="hci",
                   help="the dataset layout written (default hci; urbanlf-syn: 9x9 views, non-square sizes)")
    p.add_argument("--size", type=_size, default=None, metavar="S|WxH",
                   help="views are S x S px, or W x H px with --layout urbanlf-syn (default 128; urbanlf-syn: "
                        "640x480)")
    add_flag(p, SCENE_COUNT)
    p.add_argument("--numbers", type=_numbers, default=None, metavar="N,N,...",
                   help="--layout urbanlf-syn: the sample numbers written (Image<N>/, e.g. 11,27,34,50,54,68,69,70, "
                        "the paper's Table III samples); replaces --scenes")
    p.add_argument("--category", default=None, metavar="NAME",
                   help="category (split) folder (default synthetic; urbanlf-syn: val)")
    add_flag(p, ANGULAR)
    p.add_argument("--disparity-range", type=float, nargs=2, default=None, metavar=("LOW", "HIGH"),
                   help="disparities mapped into [LOW, HIGH] px per view step (default: urbanlf-syn -0.47 1.55, "
                        "UrbanLF-Syn's; hci the generator's own, about -2.1 2.3)")
    p.add_argument("--force", action="store_true", help="overwrite existing scene folders")
    add_flag(p, WORKERS)
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def _size(text: str) -> tuple[int, int]:
    """'S' -> (S, S); 'WxH' -> (W, H)."""
    parts = text.lower().split("x")
    if len(parts) not in (1, 2) or not all(p.strip().isdigit() for p in parts):
        raise argparse.ArgumentTypeError(f"expected S or WxH in px, e.g. 128 or 640x480, got {text[:40]!r}")
    w = int(parts[0])
    return w, int(parts[-1])


def _numbers(text: str) -> list[int]:
    """'11,27' -> [11, 27]."""
    parts = [p.strip() for p in text.split(",") if p.strip()]
    if not parts or not all(p.isdigit() and int(p) > 0 for p in parts):
        raise argparse.ArgumentTypeError(f"expected positive sample numbers, e.g. 11,27,34, got {text[:40]!r}")
    return [int(p) for p in parts]


def run(args: argparse.Namespace) -> int:
    import time

    from lfbench.data.provenance import mark_synthetic
    from lfbench.data.synth import write_benchmark
    from lfbench.utils.errors import SpecError
    from lfbench.utils.hardware import available_cores

    start = time.perf_counter()
    if args.layout == "urbanlf-syn":
        from lfbench.data.synth_urbanlf import write_urbanlf

        if args.angular != 9:
            raise SpecError("--layout urbanlf-syn writes 9x9 views: leave out --angular")
        width, height = args.size or (640, 480)
        paths = write_urbanlf(args.out, seed=args.seed, width=width, height=height, scenes=args.scenes,
                              split=args.category or "val", force=args.force, numbers=args.numbers,
                              workers=available_cores() if args.workers is None else args.workers,
                              progress=not args.no_progress,
                              **({} if args.disparity_range is None else {"disparity_range": args.disparity_range}))
        mark_synthetic(args.out, "lfbench synth --layout urbanlf-syn")
        for path in paths:
            print(path)
        print(f"wrote {len(paths)} UrbanLF-Syn sample(s) of {width}x{height} px, 9x9 views "
              f"in {time.perf_counter() - start:.1f} s")
        return 0
    if args.numbers is not None:
        raise SpecError("--numbers names UrbanLF-Syn samples: use it with --layout urbanlf-syn")
    width, height = args.size or (128, 128)
    if width != height:
        raise SpecError(f"--size {width}x{height}: the HCI layout has square views (use --layout urbanlf-syn)")
    args.size, args.category = width, args.category or "synthetic"
    paths = write_benchmark(args.out, seed=args.seed, size=args.size, scenes=args.scenes, category=args.category,
                            angular=args.angular, force=args.force, progress=not args.no_progress,
                            workers=available_cores() if args.workers is None else args.workers,
                            disparity_range=args.disparity_range)
    mark_synthetic(args.out, "lfbench synth --layout hci")
    for path in paths:
        print(path)
    print(f"wrote {len(paths)} scene(s) of {args.size}x{args.size} px, {args.angular}x{args.angular} views "
          f"in {time.perf_counter() - start:.1f} s")
    return 0
