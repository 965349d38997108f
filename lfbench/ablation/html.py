"""``lfbench ablate --html``: the HTML report (lfbench.reports.html) of an ablation folder, drawn from
OUT/results.json, the maps every cell and extra method saved (cells/<id>/maps, methods/<label>/maps)
and the spec's evaluation scenes; nothing is trained or re-run. Written to OUT/html/index.html."""

from __future__ import annotations

from pathlib import Path

from lfbench.ablation.spec import AblationSpec

__all__ = ["write_site"]


def write_site(spec: AblationSpec, out: str | Path, *, results_dir: str | Path | None = None,
               site: str | Path | None = None) -> Path:
    """Build the site of the finished ablation in ``out`` from the results.json in ``results_dir``
    (default ``out``) into ``site`` (default OUT/html); returns the path of index.html."""
    import logging

    from lfbench.ablation.cell import MAPS, load_scenes
    from lfbench.ablation.runner import prepare_evaluation
    from lfbench.reports.html import SITE_DIR, SiteInputs, build_site
    from lfbench.results import Results
    from lfbench.utils.names import file_name
    from lfbench.utils.outputs import check_within

    out = Path(out)
    results = Results.read(Path(results_dir if results_dir is not None else out))  # its results.json
    scenes = load_scenes(prepare_evaluation(spec, out, logging.getLogger(__name__).info))
    folders = {cell.id: out / "cells" / cell.id / MAPS for cell in spec.cells}
    folders |= {m.label: out / "methods" / file_name(m.label) / "maps" for m in spec.methods}
    maps = {label: folder for label, folder in folders.items() if (folder / "disp_maps").is_dir()}
    for folder in maps.values():
        check_within(folder, out, "the ablation folder")
    inputs = SiteInputs(results=results, scenes=scenes, maps=maps, title=spec.title,
                        notes=[f"Ablation {spec.source}: budget {spec.budget_label()}; one method per cell "
                               "(its id) and per extra method. Training curves: tensorboard --logdir "
                               f"{out / 'cells'}."])
    return build_site(inputs, Path(site) if site is not None else out / SITE_DIR)
