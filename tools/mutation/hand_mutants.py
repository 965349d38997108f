"""Re-run issue 25's hand-written mutations of the scoring core and the gate against the tests.

Each mutation is one textual change of one source file (the kind a refactor introduces). For each, the
package is copied to a temporary folder, the change applied there (the working tree is never touched),
and the given test files run against the copy (PYTHONPATH puts it before the editable install). A
mutation is killed when the tests fail. ``--tests`` chooses the test files: ``new`` (the issue-25 tests
named per mutation, default) or ``old`` (the files that covered scoring before them: the survivors
the issue reported). Writes a JSON report.

    python tools/mutation/hand_mutants.py --tests new --out results/mutation/hand_mutants_new.json
    python tools/mutation/hand_mutants.py --tests old --out results/mutation/hand_mutants_old.json
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
from dataclasses import asdict, dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
OLD_TESTS = ("tests/test_metrics.py", "tests/test_region_metrics.py", "tests/test_toolkit_fidelity.py",
             "tests/test_regress.py")
S, G, E = "tests/test_scoring_mutants.py", "tests/test_gate_mutants.py", "tests/test_scoring_engine.py"
M = "tests/test_scoring_engine_mutants.py"  # the issue-23 survivors' tests
# where the mutated code lives (the issue named lfbench/scoring/metrics.py and rules.py; since issue 21 the
# general metrics are in general.py, the preparation of a prediction in prepare.py, score_scene in score.py;
# since issue 23 the errors at the scored pixels in pixels.py; since issue 29 the families that reduce and resample
# a pixel-wise metric's sample in pixelwise.py)
GENERAL, PREPARE, REGION, REGRESS, PIXELS, FAMILIES = ("lfbench/scoring/general.py", "lfbench/scoring/prepare.py",
                                                       "lfbench/scoring/region_metrics.py", "lfbench/runs/regress.py",
                                                       "lfbench/scoring/pixels.py", "lfbench/scoring/pixelwise.py")
T, D = "tests/test_stats.py", "tests/test_metric_definition.py"


@dataclass(frozen=True)
class Mutation:
    id: str
    issue_class: str  # the issue's class (1-8)
    file: str
    old: str  # must occur exactly once in the file
    new: str
    tests: tuple[str, ...]  # the new tests meant to kill it


MUTATIONS = (
    # since issue 23 one comparison serves both modes (since issue 29 in BadPixels, BadPix's sample): each mode's
    # tie is mutated on its own branch
    Mutation("badpix_toolkit_ge", "1", GENERAL, "return Sample(bad)", "return Sample(px.err >= self.threshold)",
             (f"{S}::test_bad_pix_error_equal_to_the_threshold_is_good",)),
    Mutation("badpix_default_ge", "1", GENERAL, "bad |= ~px.pred_finite",
             "bad = (px.err >= self.threshold) | ~px.pred_finite",
             (f"{S}::test_bad_pix_error_equal_to_the_threshold_is_good",)),
    Mutation("badpix_curve_left", "1", GENERAL, 'side="right"', 'side="left"',
             (f"{S}::test_bad_pix_curve_counts_a_tie_as_good",)),
    Mutation("badpix_default_07", "1", GENERAL, "pred: np.ndarray, threshold: float = 0.07,",
             "pred: np.ndarray, threshold: float = 0.7,",
             (f"{S}::test_public_bad_pix_default_threshold_is_007",)),
    Mutation("fine_thinning_ge", "1", REGION, "bad = (px.gt - px.pred) > threshold",
             "bad = (px.gt - px.pred) >= threshold",
             (f"{S}::test_fine_thinning_tie_is_good",)),
    Mutation("fine_fattening_le", "1", REGION, "bad = (px.gt - px.pred) < -threshold",
             "bad = (px.gt - px.pred) <= -threshold",
             (f"{S}::test_fine_fattening_tie_is_good",)),
    Mutation("dots_badpix_ge", "1/5", REGION, "bad = np.abs(gt - pred) > threshold",
             "bad = np.abs(gt - pred) >= threshold", (f"{S}::test_missed_dots_threshold_is_04_and_strict",)),
    Mutation("bg_fattening_ge", "1", REGION, "px.pred > half if", "px.pred >= half if",
             (f"{S}::test_backgammon_prediction_exactly_half_way_is_neither_fattening_nor_thinning",)),
    Mutation("bg_thinning_le", "1", REGION, "else px.pred < half", "else px.pred <= half",
             (f"{S}::test_backgammon_prediction_exactly_half_way_is_neither_fattening_nor_thinning",)),
    Mutation("score_scene_float64", "2", PREPARE, "pred = pred.astype(np.float32, copy=False)",
             "pred = pred.astype(np.float64, copy=False)", (f"{S}::test_score_scene_scores_in_float32",)),
    Mutation("score_scene_no_cast", "2", PREPARE, "pred = pred.astype(np.float32, copy=False)", "pred = pred",
             (f"{S}::test_score_scene_scores_in_float32",)),
    Mutation("bumpiness_diff_float64", "2", REGION, "diff = (pred - gt).astype(np.float64)",
             "diff = pred.astype(np.float64) - gt.astype(np.float64)",
             (f"{S}::test_bumpiness_takes_the_difference_in_float32",)),
    # since issue 23 the region mask is combined once per scene (SceneReference.scored_mask)
    Mutation("region_replaces_mask", "3", PREPARE, "_kept(mask & self.mask(mask_name, resolution, mask.shape))",
             "_kept(self.mask(mask_name, resolution, mask.shape))",
             (f"{S}::test_region_mask_is_combined_with_the_border_and_the_valid_mask",)),
    Mutation("valid_mask_dropped", "3", PREPARE, "mask &= valid", "pass",
             (f"{S}::test_region_mask_is_combined_with_the_border_and_the_valid_mask",)),
    Mutation("border_not_scaled", "4", PREPARE, "self.rules.border_px * self.scale(resolution))",
             "self.rules.border_px)", (f"{S}::test_backgammon_metrics_at_high_resolution",)),
    # since issue 23 score_scene scores backgammon from the pixels; since issue 29 the columns exist once (the
    # samples _bg_fattened, _bg_thinned; the metrics' functions of maps derive from them)
    Mutation("bg_fg_column_unscaled", "4", REGION, "int(BACKGAMMON_FG_COLUMN * scale)", "BACKGAMMON_FG_COLUMN",
             (f"{S}::test_backgammon_metrics_at_high_resolution",)),
    Mutation("bg_fg_column_rows", "4", REGION, "scale = max(1, px.pixels.shape[1] // px.pixels.low_width)",
             "scale = max(1, px.pixels.shape[1] // px.pixels.low_width - 1)",
             (f"{S}::test_backgammon_metrics_at_high_resolution",)),
    Mutation("bg_bg_column_scaled", "4", REGION, "px.pixels.shape[1] - BACKGAMMON_BG_FROM_RIGHT,",
             "px.pixels.shape[1] - BACKGAMMON_BG_FROM_RIGHT * (px.pixels.shape[1] // px.pixels.low_width),",
             (f"{S}::test_backgammon_metrics_at_high_resolution",)),
    Mutation("bg_bg_column_lowres_width", "4", REGION, "px.pixels.shape[1] - BACKGAMMON_BG_FROM_RIGHT,",
             "px.pixels.low_width - BACKGAMMON_BG_FROM_RIGHT,", (f"{S}::test_backgammon_metrics_at_high_resolution",)),
    Mutation("dots_threshold_03", "5", REGION, "DOT_THRESHOLD = 0.4", "DOT_THRESHOLD = 0.3",
             (f"{S}::test_missed_dots_threshold_is_04_and_strict",)),
    Mutation("percent_bad_nonfinite_gt", "6", REGION, "return kept(bad, reference_finite)", "return Sample(bad)",
             (f"{S}::test_region_metrics_leave_out_nonfinite_ground_truth",)),
    Mutation("dots_nonfinite_gt", "6", REGION, "scored = np.isfinite(gt)", "scored = np.ones(gt.shape, bool)",
             (f"{S}::test_missed_dots_leave_out_nonfinite_ground_truth",)),
    Mutation("mae_nonfinite_gt", "6", REGION, "scored = mask & np.isfinite(n_gt).all(axis=-1)", "scored = mask",
             (f"{S}::test_mae_and_bumpiness_leave_out_nonfinite_ground_truth",)),
    Mutation("bumpiness_nonfinite_gt", "6", REGION, "scored = mask & gt_ok", "scored = mask",
             (f"{S}::test_mae_and_bumpiness_leave_out_nonfinite_ground_truth",)),
    Mutation("gate_worse_ge", "7", REGRESS, "if change > g.tolerance:", "if change >= g.tolerance:",
             (f"{G}::test_unmatched_metric_gets_tolerance_zero_and_identical_results_pass",)),
    Mutation("gate_better_le", "7", REGRESS, "elif change < -g.tolerance:", "elif change <= -g.tolerance:",
             (f"{G}::test_unmatched_metric_gets_tolerance_zero_and_identical_results_pass",)),
    Mutation("gate_default_tolerance", "7", REGRESS, "            return float(value)\n    return 0.0",
             "            return float(value)\n    return 0.01",
             (f"{G}::test_unmatched_metric_gets_tolerance_zero_and_identical_results_pass",)),
    Mutation("gate_no_sort", "7", REGRESS, "findings.sort(key=lambda f: not f.failed)", "pass",
             (f"{G}::test_findings_list_failures_first_in_golden_order",)),
    Mutation("gate_sort_reversed", "7", REGRESS, "findings.sort(key=lambda f: not f.failed)",
             "findings.sort(key=lambda f: f.failed)", (f"{G}::test_findings_list_failures_first_in_golden_order",)),
    Mutation("make_golden_keeps_nan", "7", REGRESS, "for r in results.records if math.isfinite(r.value)]",
             "for r in results.records]", (f"{G}::test_make_golden_leaves_out_nonfinite_values",)),
    Mutation("make_golden_allow_nan", "7", REGRESS, "for r in results.records if math.isfinite(r.value)]",
             "for r in results.records]\n    records = json.loads(json.dumps(records))  # NaN kept",
             (f"{G}::test_make_golden_leaves_out_nonfinite_values",)),
    Mutation("fine_fattening_sign_swap", "8", REGION, "bad = (px.gt - px.pred) < -threshold",
             "bad = (px.pred - px.gt) < -threshold", (f"{S}::test_fine_fattening_is_not_symmetric_with_thinning",)),
    Mutation("fine_fattening_abs", "8", REGION, "bad = (px.gt - px.pred) < -threshold",
             "bad = np.abs(px.gt - px.pred) > threshold",
             (f"{S}::test_fine_fattening_is_not_symmetric_with_thinning",)),
    # 9: properties, which mutmut does not mutate (it skips every decorated function but static and class
    # methods): the errors every pixel-wise metric computes from (issue 23), changed as classes 2, 3 and 6 change
    # the code that computed them before
    Mutation("errors_signed", "9", PIXELS, "return np.abs(err, out=err)", "return err",
             (f"{E}::test_pixelwise_metrics_are_the_formulas_on_the_maps",)),
    Mutation("errors_float64", "9/2", PIXELS, "err = np.subtract(self.pred, self.gt)",
             "err = np.subtract(self.pred, self.gt, dtype=np.float64)",
             (f"{S}::test_score_scene_scores_in_float32",)),
    Mutation("errors_gt_finite_nan_only", "9/6", PIXELS, "return np.isfinite(self.gt)", "return ~np.isnan(self.gt)",
             (f"{M}::test_infinite_ground_truth_is_not_scored",)),
    Mutation("errors_pred_finite_nan_only", "9/6", PIXELS, "return np.isfinite(self.pred)",
             "return ~np.isnan(self.pred)", (f"{E}::test_pixelwise_metrics_are_the_formulas_on_the_maps",)),
    Mutation("errors_finite_gt_only", "9/6", PIXELS, "return self.gt_finite & self.pred_finite",
             "return self.gt_finite", (f"{E}::test_pixelwise_metrics_are_the_formulas_on_the_maps",)),
    Mutation("errors_size_all_pixels", "9/3", PIXELS,
             "def size(self) -> int:\n        return int(self.gt.size)\n\n    @functools.cached_property\n    def err",
             "def size(self) -> int:\n        return int(self.pixels.gt_map.size)\n\n    @functools.cached_property\n"
             "    def err",  # since issue 29 no built-in metric reads it (a sample counts its own values)
             (f"{D}::test_a_metric_defined_once_is_a_function_of_maps_and_bootstraps_in_its_family",)),
    Mutation("pixel_set_size_all_pixels", "9/3", PIXELS,
             "def size(self) -> int:\n        return int(self.gt.size)\n\n    def memo",
             "def size(self) -> int:\n        return int(self.gt_map.size)\n\n    def memo",
             (f"{S}::test_backgammon_metrics_at_high_resolution",)),
    Mutation("pixel_set_gt_unmasked", "9/3", PIXELS,
             "self.gt_map.ravel() if self.mask is None else self.gt_map[self.mask]", "self.gt_map.ravel()",
             (f"{S}::test_region_mask_is_combined_with_the_border_and_the_valid_mask",)),
    Mutation("prepared_pred_not_upsampled", "9/4", PREPARE,
             "return _kept(self.reference.upsample(self.aligned, self.resolution))", "return _kept(self.aligned)",
             (f"{E}::test_one_reference_scores_each_prediction_as_a_reference_of_its_own",)),
    # 10: the resampling families (issue 29): how every pixel-wise metric's sample reduces to its value, and the
    # errors-only view the bootstrap draws the samples from
    Mutation("proportion_unscaled", "10/2", FAMILIES, "else self.scale * int(np.count_nonzero(values))",
             "else int(np.count_nonzero(values))", (f"{S}::test_bad_pix_error_equal_to_the_threshold_is_good",)),
    Mutation("order_statistic_next", "10/1", FAMILIES, "k = int(values.size * self.percentage / 100.0)",
             "k = min(values.size - 1, int(values.size * self.percentage / 100.0) + 1)",
             ("tests/test_toolkit_runtime_quantile.py::test_quantile_family_is_the_element_at_int_n_p_over_100",)),
    Mutation("mean_in_float64", "10/2", FAMILIES, "float(np.average(values)) * self.scale",
             "float(np.mean(values, dtype=np.float64)) * self.scale",
             (f"{D}::test_mse_is_the_float32_mean_times_100",)),
    Mutation("errors_only_nan_only", "10/6", PIXELS, "return np.isfinite(self.signed)", "return ~np.isnan(self.signed)",
             (f"{T}::test_estimate_equals_metrics_module",)),
)


def run_tests(package_root: Path, tests: list[str]) -> int:
    env = {**os.environ, "PYTHONPATH": str(package_root)}
    # -P: no current folder on sys.path (it would put the unmutated package first)
    cmd = [sys.executable, "-P", "-m", "pytest", "-q", "-x", "-p", "no:cacheprovider", *tests]
    return subprocess.run(cmd, cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL).returncode


def check_mutation(m: Mutation, tests: list[str]) -> bool:
    """True when ``tests`` fail with ``m`` applied (killed)."""
    with tempfile.TemporaryDirectory(prefix="lfbench-mutant-") as tmp:
        copy = Path(tmp) / "lfbench"
        shutil.copytree(ROOT / "lfbench", copy, ignore=shutil.ignore_patterns("__pycache__"))
        path = Path(tmp) / m.file
        text = path.read_text(encoding="utf-8")
        if text.count(m.old) != 1:
            raise SystemExit(f"{m.id}: {m.old!r} occurs {text.count(m.old)} times in {m.file}, expected once")
        path.write_text(text.replace(m.old, m.new), encoding="utf-8")
        return run_tests(Path(tmp), tests) != 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tests", choices=("new", "old"), default="new")
    parser.add_argument("--only", nargs="*", help="mutation ids (default: all)")
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()
    chosen = [m for m in MUTATIONS if not args.only or m.id in args.only]
    with tempfile.TemporaryDirectory(prefix="lfbench-clean-") as tmp:  # the clean copy must pass
        shutil.copytree(ROOT / "lfbench", Path(tmp) / "lfbench", ignore=shutil.ignore_patterns("__pycache__"))
        where = subprocess.run([sys.executable, "-P", "-c", "import lfbench; print(lfbench.__file__)"], cwd=ROOT,
                               env={**os.environ, "PYTHONPATH": tmp}, capture_output=True, text=True).stdout
        if not where.startswith(tmp):
            raise SystemExit(f"the tests would not import the copy under {tmp}: lfbench is {where.strip()}")
        clean_tests = list(OLD_TESTS) if args.tests == "old" else sorted({t.split("::")[0] for m in chosen
                                                                           for t in m.tests})
        if run_tests(Path(tmp), clean_tests) != 0:
            raise SystemExit("the tests fail without any mutation")
    rows = []
    for m in chosen:
        tests = list(OLD_TESTS) if args.tests == "old" else list(m.tests)
        killed = check_mutation(m, tests)
        rows.append({**asdict(m), "tests_run": tests, "killed": killed})
        print(f"{'killed  ' if killed else 'SURVIVED'} {m.id}", flush=True)
    args.out.write_text(json.dumps(rows, indent=1) + "\n", encoding="utf-8")
    n_killed = sum(r["killed"] for r in rows)
    print(f"{n_killed} of {len(rows)} killed ({args.tests} tests)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
