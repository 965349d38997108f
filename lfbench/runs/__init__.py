"""Runs: methods run on scenes and scored scene by scene (runner; in worker processes through
lfbench.utils.executor.ProcessPool) into a folder with the chosen output writers (folder:
``evaluate_to_folder``), golden regression checks (regress), the offline demo (demo) and speed/memory benchmarks
(bench). Import from the modules (``lfbench.runs.folder.evaluate_to_folder``): the package itself imports nothing,
since the command line reads the demo's defaults at start-up. The results data model is :mod:`lfbench.results`."""
