"""Predict a disparity map with one method for one light field (a scene folder or VIEWS.npy).

VIEWS.npy is float (H, W, N) gray in [0, 1] of a square A x A grid (N = A^2: 81 for 9x9, 49 for 7x7), channel
k = view k (row-major: view (v, u) is channel v * A + u). The output is a PFM
(submission format) or a .npy; with --extras the distribution and uncertainty are saved beside it.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from lfbench.cli.argtypes import add_flag
from lfbench.utils.flags import DEVICE

MAX_ANGULAR = 33  # views per side of a VIEWS.npy grid

HELP = "predict a disparity map for a scene or sample folder or a VIEWS.npy"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--method", required=True, metavar="SPEC", help="method spec name[:key=value,...]")
    p.add_argument("--input", required=True, type=Path,
                   help="scene folder (HCI layout), UrbanLF-Syn sample folder (ImageN/) or "
                        "VIEWS.npy (H, W, N) of an A x A grid, N = A^2")
    p.add_argument("--out", required=True, type=Path, help="OUT.pfm or OUT.npy")
    add_flag(p, DEVICE, detail="every method that has a device parameter (a spec's own device=... wins; default: "
                               "the method's, auto)")
    p.add_argument("--extras", action="store_true",
                   help="also save OUT.distribution.npy (D, H, W), OUT.disparities.npy (D,) and OUT.uncertainty.npy")


def load_input(path: Path):
    """A LightField from a scene folder or a VIEWS.npy; DataError naming the file otherwise."""
    import math

    import numpy as np

    from lfbench.data.dataset import open_dataset
    from lfbench.data.npyfile import read_npy
    from lfbench.data.scene import MAX_RESOLUTION_PX, MAX_VIEW_PIXELS, ArrayLightField
    from lfbench.utils.errors import DataError

    if path.is_dir():  # one scene folder of any dataset layout (lfbench datasets)
        _, bench = open_dataset(path)
        if len(bench.scenes) != 1:
            raise DataError(f"holds {len(bench.scenes)} scenes: give one scene folder", path)
        return bench.scenes[0]
    if path.suffix != ".npy":
        raise DataError("input must be a scene folder or a .npy file", path)

    def check(shape: tuple[int, ...], dtype: np.dtype) -> str | None:
        side = math.isqrt(shape[2]) if len(shape) == 3 else 0
        if len(shape) != 3 or side * side != shape[2] or not 2 <= side <= MAX_ANGULAR:
            return (f"expected (H, W, N) views of a square A x A grid (N = A^2, A from 2 to {MAX_ANGULAR}, e.g. 81 "
                    f"for 9x9), got shape {shape}")
        if not 1 <= min(shape[:2]) or max(shape[:2]) > MAX_RESOLUTION_PX or math.prod(shape) > MAX_VIEW_PIXELS:
            return (f"views of {shape[1]}x{shape[0]} px: each side must be from 1 to {MAX_RESOLUTION_PX} "
                    f"and all {shape[2]} views at most {MAX_VIEW_PIXELS} px")
        if not np.issubdtype(dtype, np.floating):
            return f"views must be floating-point values in [0, 1], got {dtype}"
        return None

    arr = read_npy(path, check)
    if not np.isfinite(arr).all():
        raise DataError("views must be finite floating-point values in [0, 1]", path)
    return ArrayLightField.from_channels(arr.astype(np.float32), name=path.stem)


#: The files ``--extras`` writes beside OUT (OUT without its suffix, then these).
EXTRAS = (".distribution.npy", ".disparities.npy", ".uncertainty.npy")


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from lfbench.data.pfm import write_pfm
    from lfbench.method.registry import create_from_spec
    from lfbench.utils.atomic import atomic_open
    from lfbench.utils.errors import DataError
    from lfbench.utils.outputs import check_output_file

    if args.out.suffix not in (".pfm", ".npy"):
        raise DataError("output must end in .pfm or .npy", args.out)
    args.out = check_output_file(args.out)  # before the work (a link: the file it leads to)
    if args.extras:
        stem = args.out.with_suffix("")
        for suffix in EXTRAS:
            check_output_file(Path(f"{stem}{suffix}"))
    method = create_from_spec(args.method, {"device": args.device})
    lf = load_input(args.input)
    reason = method.available_for(lf)
    if reason:
        raise DataError(f"{method.label} cannot run on this input: {reason}", args.input)
    pred = method.run(lf)  # the one check of a prediction: real floating values, the light field's size

    def save(path: Path, arr) -> None:
        with atomic_open(path, "wb") as f:
            np.save(f, np.asarray(arr))

    if args.out.suffix == ".pfm":
        write_pfm(args.out, pred.disparity)
    else:
        save(args.out, pred.disparity)
    if args.extras:
        stem = args.out.with_suffix("")
        for suffix, arr in zip(EXTRAS, (pred.distribution, pred.disparity_values, pred.uncertainty), strict=True):
            if arr is not None:
                save(check_output_file(Path(f"{stem}{suffix}")), arr)
    nonfinite = int(pred.disparity.size - np.count_nonzero(np.isfinite(pred.disparity)))
    counted = f", {nonfinite} non-finite pixels" if nonfinite else ""
    print(f"{method.label}: wrote {args.out} ({pred.disparity.shape[1]}x{pred.disparity.shape[0]}, "
          f"{pred.runtime_s:.2f} s{counted})")
    return 0
