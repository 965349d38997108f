"""``lfbench convert-keras FILE OUT.pt``: turn an authors' Keras checkpoint (HDF5 of ``model.save`` or
``save_weights``) into lfbench weights, recognising the network the file holds from its layers:

- EPINET (chshin10/epinet; layers ``S1_c1<i>`` .. ``S3_last`` in nested Sequential models): weights for
  ``epinet:weights=OUT.pt``; angular size, filters and depth from the arrays' shapes;
- SubFocal / LFattNet (a nested feature extractor and eight 3x3x3 Conv3D layers): weights for
  ``subfocal:weights=OUT.pt`` (or ``lfattnet``). Their disparity grid is not stored in the weights: give
  ``--interval 1`` (or ``--network lfattnet``) for LFattNet (default 0.5, SubFocal's) and ``--d-min`` /
  ``--d-max`` (default -4 / 4).

``--network NAME`` / ``--angular N`` say what the file must hold: another network or angular size is one
line naming the file and what it holds (exit 2), and nothing is written.

A plugin command: it comes from the ``lfbench.commands`` entry point of this package (pyproject.toml), the
way any plugin adds a subcommand (see lfbench/cli/__init__.py). Examples:

    lfbench convert-keras iter0050_valmse0.800_bp2.00.hdf5 subfocal_paper.pt
    lfbench convert-keras iter10000_mse1.504_bp3.65.hdf5 epinet_authors.pt --network epinet
    lfbench predict --method epinet:weights=epinet_authors.pt --input SCENE --out OUT.pfm
"""

from __future__ import annotations

import argparse
from pathlib import Path

HELP = "convert an authors' Keras .hdf5 checkpoint (SubFocal, LFattNet, EPINET) into lfbench weights"
NETWORKS = ("subfocal", "lfattnet", "epinet")
SUBFOCAL_GRID = {"interval": 0.5, "d_min": -4.0, "d_max": 4.0}  # SubFocal's defaults (LFattNet: interval 1)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("checkpoint", type=Path, help="Keras HDF5 checkpoint (model.save / save_weights)")
    p.add_argument("out", type=Path, help="output .pt (state_dict, config, source)")
    p.add_argument("--network", choices=NETWORKS, default=None,
                   help="the network the file must hold (default: whichever it holds)")
    p.add_argument("--angular", type=int, default=None,
                   help="the views per angular row it must have (default: its own)")
    p.add_argument("--interval", type=float, default=None,
                   help="SubFocal/LFattNet: disparity interval in px (SubFocal 0.5, the default; LFattNet 1, the "
                        "default with --network lfattnet)")
    p.add_argument("--d-min", type=float, default=None, help="SubFocal/LFattNet: smallest disparity of the grid (px, "
                                                             "default -4)")
    p.add_argument("--d-max", type=float, default=None, help="SubFocal/LFattNet: largest disparity of the grid (px, "
                                                             "default 4)")


def run(args: argparse.Namespace) -> int:
    from lfbench_methods.epinet.keras_import import holds_epinet

    from lfbench.utils.errors import DataError, SpecError
    from lfbench.utils.outputs import check_output_file

    if args.angular is not None and not 1 <= args.angular <= 33:
        raise SpecError(f"--angular must be from 1 to 33, got {args.angular}")
    grid = {"interval": args.interval, "d_min": args.d_min, "d_max": args.d_max}
    epinet = holds_epinet(args.checkpoint)
    if epinet and args.network not in (None, "epinet"):
        raise DataError(f"an EPINET Keras checkpoint, not {args.network}", args.checkpoint)
    if not epinet and args.network == "epinet":
        raise DataError("not an EPINET Keras checkpoint (no layers S1_c10 .. S3_last)", args.checkpoint)
    if epinet and any(v is not None for v in grid.values()):
        raise DataError("an EPINET Keras checkpoint: --interval / --d-min / --d-max do not apply (EPINET regresses "
                        "the disparity directly, without a disparity grid)", args.checkpoint)
    args.out = check_output_file(args.out)  # before the work (a link: the file it leads to)
    return (_epinet if epinet else _subfocal)(args, grid)


def _epinet(args: argparse.Namespace, grid: dict) -> int:
    from lfbench_methods.epinet.keras_import import describe, load_keras_epinet
    from lfbench_methods.epinet.network import count_trainable

    from lfbench.training.checkpoint import export_weights

    net = load_keras_epinet(args.checkpoint, angular=args.angular)
    export_weights(args.out, net, {"source": f"keras:{args.checkpoint.name}"}, method="epinet", config=net.config())
    print(f"wrote {args.out}: {describe(net.config())[3:]}, {count_trainable(net)} trainable parameters")
    return 0


def _subfocal(args: argparse.Namespace, grid: dict) -> int:
    from lfbench_methods.subfocal.keras_import import load_keras_checkpoint, save_checkpoint
    from lfbench_methods.subfocal.network import count_trainable

    from lfbench.data.shift import disparity_grid
    from lfbench.utils.errors import DataError, SpecError

    defaults = {**SUBFOCAL_GRID, "interval": 1.0} if args.network == "lfattnet" else SUBFOCAL_GRID
    grid = {k: defaults[k] if v is None else v for k, v in grid.items()}
    try:
        disparity_grid(grid["d_min"], grid["d_max"], grid["interval"])
    except ValueError as exc:
        raise SpecError(f"bad disparity grid: {exc}") from None
    net = load_keras_checkpoint(args.checkpoint, **grid)
    cfg = net.config()
    if args.angular is not None and args.angular != cfg["angular"]:
        raise DataError(f"a SubFocal/LFattNet Keras checkpoint of {cfg['angular']}x{cfg['angular']} views, not "
                        f"{args.angular}x{args.angular}", args.checkpoint)
    save_checkpoint(net, args.out, source=f"keras:{args.checkpoint.name}")
    print(f"wrote {args.out}: width {cfg['width']}, attention {cfg['attention']}, "
          f"{net.disparities.numel()} disparities in [{cfg['d_min']:g}, {cfg['d_max']:g}] step {cfg['interval']:g}, "
          f"{count_trainable(net)} trainable parameters")
    return 0
