"""Convert a Keras checkpoint of the SubFocal/LFattNet authors' code (HDF5 written by ``model.save``,
with model_weights/) into a PyTorch checkpoint for the ``subfocal`` method.

A plugin command: ``lfbench convert-keras`` comes from the ``lfbench.commands`` entry point of this
package (pyproject.toml), the way any plugin adds a subcommand (see lfbench/cli/__init__.py).

The disparity grid is not stored in the Keras weights: give --interval 1 for LFattNet checkpoints
(the default 0.5 is SubFocal's). Example:

    lfbench convert-keras iter0050_valmse0.800_bp2.00.hdf5 subfocal_paper.pt
    lfbench predict --method subfocal:weights=subfocal_paper.pt --input SCENE --out OUT.pfm
"""

from __future__ import annotations

import argparse
from pathlib import Path

HELP = "convert an authors' Keras .hdf5 checkpoint into weights for the subfocal method"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("checkpoint", type=Path, help="Keras HDF5 checkpoint (model.save, with model_weights/)")
    p.add_argument("out", type=Path, help="output .pt (state_dict, config, source)")
    p.add_argument("--interval", type=float, default=0.5, help="disparity interval in px (SubFocal 0.5, LFattNet 1)")
    p.add_argument("--d-min", type=float, default=-4.0, help="smallest disparity of the grid in px (default -4)")
    p.add_argument("--d-max", type=float, default=4.0, help="largest disparity of the grid in px (default 4)")


def run(args: argparse.Namespace) -> int:
    from lfbench_methods.subfocal.keras_import import load_keras_checkpoint, save_checkpoint
    from lfbench_methods.subfocal.network import count_trainable

    from lfbench.utils.errors import SpecError

    try:
        from lfbench.data.shift import disparity_grid

        disparity_grid(args.d_min, args.d_max, args.interval)
    except ValueError as exc:
        raise SpecError(f"bad disparity grid: {exc}") from None
    from lfbench.utils.outputs import check_output_file

    args.out = check_output_file(args.out)  # before the work (a link: the file it leads to)
    net = load_keras_checkpoint(args.checkpoint, interval=args.interval, d_min=args.d_min, d_max=args.d_max)
    save_checkpoint(net, args.out, source=f"keras:{args.checkpoint.name}")
    cfg = net.config()
    print(f"wrote {args.out}: width {cfg['width']}, attention {cfg['attention']}, "
          f"{net.disparities.numel()} disparities in [{cfg['d_min']:g}, {cfg['d_max']:g}] step {cfg['interval']:g}, "
          f"{count_trainable(net)} trainable parameters")
    return 0
