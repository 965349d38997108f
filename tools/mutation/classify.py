"""Give every surviving mutant of `nox -s mutation` its reason, and fail if one has none.

Reads mutmut's survivors (mutants/, as survivors.py does) and the fresh-process re-check
(recheck_import_time.json); writes a Markdown table, one row per survivor: mutant, change, reason.
Three reasons are recognised from the change itself (the same rule for every mutant it matches); the
others are listed by mutant name below, each with why the change cannot alter a score, a results
record or a gate decision. A survivor with no reason is printed as UNEXPLAINED and the exit code is 1:
either a test is missing or the reason must be written here.

A few survivors may be known but not equivalent: a test could kill them, but none that the fast suite can run
(each entry says why). They are listed in KNOWN_NOT_KILLED; their reason begins with "not killed (known,
not equivalent): ", they appear in the table and its summary under that label and are counted apart in the
last line, and they do not fail the run.

    python tools/mutation/classify.py --recheck results/mutation/recheck_import_time.json \\
        --out results/mutation/survivors_classified.md
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
from survivors import ROOT, SURVIVED, survivors  # noqa: E402

PRESENTATION = ("presentation only: a metric's display name, description or colour-map setting (figure labels "
                "and colour ranges; never a score, a results record or a gate decision)")
COPY = ("equivalent: `astype`'s `copy` flag; no caller writes into the arrays, so a copy or a view gives the "
        "same numbers")
NAN = 'equivalent: `float("NAN")` is `float("nan")`'

_SEEN_AT = "lfbench."
REASONS: dict[str, tuple[str, ...]] = {
    "equivalent: NumPy comparisons raise no floating-point exception (NaN compares False silently), so "
    "ignoring `invalid` around a comparison changes nothing": (
        "scoring.general.x_bad_pix_of__mutmut_3",
        "scoring.region_metrics.x__backgammon_sample__mutmut_6",
        "scoring.general.x_bad_pix__mutmut_16", "scoring.general.x_bad_pix__mutmut_33",
        "scoring.region_metrics.x_backgammon_fattening__mutmut_14",
        "scoring.region_metrics.x_backgammon_thinning__mutmut_14",
        "scoring.general.xǁBadPixelsǁ__call____mutmut_3", "scoring.general.xǁBadPixelsǁ__call____mutmut_18"),
    "equivalent: the floating-point exception this `errstate` entry silences cannot occur there: `divide` "
    "needs x / 0 with x != 0 (a normal is 0 only when all its components are; n_bad <= n); `over` needs "
    "1 / d with 0 < |d| < 3e-39 in disp2depth, whose float32 denominator is 0 or >= ~1e-9; the gt-finiteness "
    "map is 0 or NaN, whose filtering raises nothing": (
        "scoring.region_metrics.x_disparity_normals__mutmut_3",
        "scoring.region_metrics.x_disparity_normals__mutmut_6",
        "scoring.region_metrics.xǁDotLayoutǁmissed__mutmut_38",
        "scoring.region_metrics.xǁDotLayoutǁmissed__mutmut_40",
        "scoring.region_metrics.x_missed_dots__mutmut_118", "scoring.region_metrics.x_missed_dots__mutmut_120",
        "scoring.region_metrics.x_median_angular_error__mutmut_11",
        "scoring.region_metrics.x_median_angular_error__mutmut_14",
        "scoring.region_metrics.x__gt_bump_ok__mutmut_3"),
    "equivalent: a default that is never used: every metric is called through Metric.__call__, which always "
    "passes `toolkit=` (a pixel-wise sample through PixelMetric, which does too); mse_x100 ignores `toolkit` "
    "(MSE has one rule: squared_error never reads it)": (
        "scoring.general.x__quantile_metric__mutmut_1", "scoring.general.x__quantile_metric__mutmut_12",
        "scoring.general.x_bad_pix_metric__mutmut_14", "scoring.region_metrics.x__bad_pix_pixels__mutmut_1",
        "scoring.general.x_mse_x100__mutmut_3",
        "scoring.general.x_mse_x100__mutmut_5",
        "scoring.general.x_mse_x100_of__mutmut_1", "scoring.general.x_mse_x100_of__mutmut_3",
        "scoring.general.x_mse_x100_of__mutmut_5",
        "scoring.general.x__q25_of__mutmut_1",
        "scoring.region_metrics.x__fattened__mutmut_1",
        "scoring.region_metrics.x__thinned__mutmut_1",
        "scoring.region_metrics.x__bg_fattened__mutmut_1",
        "scoring.region_metrics.x__bg_thinned__mutmut_1",
        "scoring.region_metrics.xǁDotLayoutǁmissed__mutmut_1",
        "scoring.general.x_mse_x100__mutmut_1", "scoring.general.x_bad_pix_metric__mutmut_3",
        "scoring.region_metrics.x__bad_pix_fn__mutmut_1", "scoring.region_metrics.x__bump_fn__mutmut_1",
        "scoring.region_metrics.x__mae_fn__mutmut_1", "scoring.region_metrics.x__fine_fat_fn__mutmut_1",
        "scoring.region_metrics.x__fine_thin_fn__mutmut_1", "scoring.region_metrics.x__bg_fat_fn__mutmut_1",
        "scoring.region_metrics.x__bg_thin_fn__mutmut_1", "scoring.region_metrics.x__missed_dots_fn__mutmut_1",
        "scoring.region_metrics.x__slanted_fn__mutmut_1"),
    "equivalent: the dtype is already the one named (astype(None) and np.asarray without dtype give float64 / "
    "intp here; _scharr_separable's inputs are float64; depth_normals' depth reaches the filters only through "
    "_scharr_separable, which casts it to float64 exactly); np.full(..., None, float32) is NaN; a float "
    "zeros(1) behaves as False": (
        "scoring.region_metrics.x__first_labels__mutmut_12",
        "scoring.region_metrics.x__first_labels__mutmut_15",
        "scoring.region_metrics.x__halfway_of__mutmut_4",
        "scoring.region_metrics.x__halfway_of__mutmut_5",
        "scoring.region_metrics.x__halfway_of__mutmut_8",
        "scoring.region_metrics.x_bumpiness_map__mutmut_11", "scoring.region_metrics.x__halfway_to_column__mutmut_4",
        "scoring.region_metrics.x__scharr_separable__mutmut_11",
        "scoring.region_metrics.x__scharr_separable__mutmut_13",
        "scoring.region_metrics.x_depth_normals__mutmut_3", "scoring.region_metrics.x_depth_normals__mutmut_5",
        "scoring.region_metrics.x__first_labels__mutmut_13", "scoring.region_metrics.x__first_labels__mutmut_16",
        "scoring.region_metrics.x__label_lut__mutmut_13", "scoring.region_metrics.x__label_lut__mutmut_15",
        "scoring.prepare.x_align_prediction__mutmut_53"),
    "equivalent: scharr_derivative treats every axis other than 0 as 1 (axis=None or 2 is the `else` branch)": (
        "scoring.region_metrics.x__hessian_norm__mutmut_3", "scoring.region_metrics.x__hessian_norm__mutmut_6",
        "scoring.region_metrics.x__hessian_norm__mutmut_15", "scoring.region_metrics.x__hessian_norm__mutmut_18",
        "scoring.region_metrics.x__hessian_norm__mutmut_30", "scoring.region_metrics.x__hessian_norm__mutmut_33"),
    "equivalent: a lookup table only needs one entry per label value and -1 (any negative) elsewhere: a longer "
    "table, a -2 fill, an empty-label table of 2 entries or `present[:lowest] = None` (False) change no "
    "lookup; `highest` is None for the only caller (boxes), so its branch never runs": (
        "scoring.region_metrics.x__first_labels__mutmut_20",
        "scoring.region_metrics.x__first_labels__mutmut_21",
        "scoring.region_metrics.x__first_labels__mutmut_23",
        "scoring.region_metrics.x__label_lut__mutmut_3",
        "scoring.region_metrics.x__label_lut__mutmut_6",
        "scoring.region_metrics.x__label_lut__mutmut_7",
        "scoring.region_metrics.x__label_lut__mutmut_8",
        "scoring.region_metrics.x__label_lut__mutmut_9",
        "scoring.region_metrics.x__present__mutmut_11",
        "scoring.region_metrics.x__present__mutmut_12",
        "scoring.region_metrics.x__first_labels__mutmut_25", "scoring.region_metrics.x__first_labels__mutmut_26",
        "scoring.region_metrics.x__first_labels__mutmut_27", "scoring.region_metrics.x__first_labels__mutmut_28",
        "scoring.region_metrics.x__first_labels__mutmut_30", "scoring.region_metrics.x__label_lut__mutmut_16",
        "scoring.region_metrics.x__label_lut__mutmut_17", "scoring.region_metrics.x__label_lut__mutmut_20",
        "scoring.region_metrics.x__label_lut__mutmut_21", "scoring.region_metrics.x__label_lut__mutmut_22",
        "scoring.region_metrics.x__label_lut__mutmut_23"),
    "equivalent: the same numbers by arithmetic: norms are >= 0 (clip's lower bound), a constant map has a zero "
    "Hessian, np.where(..., None) is cast to NaN, NaN >= 50 is False when n == 0, int(14 * 10.0) == 140, "
    "zoom by 10.0 == zoom by 10, zoom by 1 is the identity, an even crop halves exactly (odd ones were "
    "refused), the channels are equal after the gray check, the condition reduces to `not text.isdigit()`, "
    "an empty error list returns before the thresholds are used, reading mask names when none is needed "
    "changes nothing, ndimage.convolve's default mode is the default 'reflect'": (
        "scoring.region_metrics.xǁDotLayoutǁmissed__mutmut_51",
        "scoring.region_metrics.x__bg_fattened__mutmut_8",
        "scoring.region_metrics.x_bumpiness_map__mutmut_14", "scoring.region_metrics.x__gt_bump_ok__mutmut_10",
        "scoring.region_metrics.x__gt_bump_ok__mutmut_14", "scoring.region_metrics.x_missed_dots__mutmut_131",
        "scoring.region_metrics.x__scale__mutmut_6", "scoring.prepare.x_align_prediction__mutmut_34",
        "scoring.prepare.x_read_label_mask__mutmut_24",
        "scoring.prepare.xǁSceneReferenceǁprepare__mutmut_26", "scoring.prepare.xǁSceneReferenceǁprepare__mutmut_48",
        "scoring.prepare.xǁSceneReferenceǁvalid_mask__mutmut_21",
        "scoring.general.x_bad_pix_curve__mutmut_29", "scoring.rules.x_metric_resolution__mutmut_8",
        "scoring.region_metrics.x_scharr_derivative__mutmut_15"),
    "equivalent for every id: `badpix_<t>` ids have one '_'; the split differs only for ids with a second one, "
    "which badpix_family refuses either way (since issue 31 it returns a metric only when the id is that metric's "
    "own id or toolkit id, neither of which has a second '_')": (
        "scoring.general.x_badpix_family__mutmut_10", "scoring.general.x_badpix_family__mutmut_11",
        "scoring.general.x_badpix_family__mutmut_13"),
    "unreachable (defensive) code: Scene.mask reads a mask with its expected size and refuses any other "
    "(lfbench.data.scene.read_mask) before this check (SceneReference.mask's shape check serves light fields "
    "whose masks are not read by Scene); Scene.valid_mask refuses any size but the scene's, and a high-res "
    "ground truth is read with its size checked, so the valid mask always scales by an integer; "
    "metric_resolution returns high resolution only when the high-res gt exists": (
        "scoring.prepare.xǁSceneReferenceǁscored_mask__mutmut_12",
        "scoring.prepare.xǁSceneReferenceǁscored_mask__mutmut_15",
        "scoring.prepare.xǁSceneReferenceǁupsample_index__mutmut_10",
        "scoring.prepare.xǁSceneReferenceǁupsample_index__mutmut_11",
        "scoring.prepare.xǁSceneReferenceǁupsample_index__mutmut_12",
        "scoring.prepare.xǁSceneReferenceǁupsample_index__mutmut_13",
        "scoring.prepare.xǁSceneReferenceǁupsample_index__mutmut_14",
        "scoring.prepare.xǁSceneReferenceǁupsample_index__mutmut_15",
        "scoring.score.x_score_scene__mutmut_43", "scoring.score.x_score_scene__mutmut_61",
        "scoring.score.x_score_scene__mutmut_64", "scoring.region_metrics.x__slanted_fn__mutmut_13",
        "scoring.region_metrics.x__slanted_fn__mutmut_16",
        *(f"scoring.prepare.xǁSceneReferenceǁmask__mutmut_{i}" for i in (10, 11, 12)),
        *(f"scoring.prepare.xǁSceneReferenceǁvalid_mask__mutmut_{i}" for i in (23, 24, 25, 29, 30, 31)),
    ),
    "equivalent: score_scene aligns the prediction (and refuses it, naming its source) before it prepares "
    "it: the source given to prepare names a prediction that can no longer fail": (
        "scoring.score.x_score_scene__mutmut_47", "scoring.score.x_score_scene__mutmut_50"),
    "equivalent: a comparison with NaN is False, so `not low < high` alone already refuses a NaN end of "
    "value_range": ("scoring.base.xǁMetricǁ__post_init____mutmut_7",),
    "equivalent: NumPy sets a flag to the truth value it is given (`writeable = None` is False)": (
        "scoring.pixels.x__read_only__mutmut_1",
        "scoring.prepare.x__kept__mutmut_4",),
    "equivalent while SCENE_AGGREGATES has one entry ('mean'): the separator of a one-item join never "
    "appears in the message": ("scoring.base.xǁMetricǁ__post_init____mutmut_4",),
    "equivalent: the default of the own-code test's getattr(fn, '__module__', ...) for an fn without a __module__ "
    "attribute: '', 'None' (str of None) and 'XXXX' all have a first dotted part other than 'lfbench', so such an "
    "fn is a plugin's (guarded) either way": (
        "scoring.base.xǁMetricǁ__call____mutmut_9", "scoring.base.xǁMetricǁ__call____mutmut_15"),
    "equivalent: `dtype.kind not in \"XXbiufXX\"`: a dtype's kind is one character and no NumPy kind is 'X', so "
    "it is in the string exactly when it is in \"biuf\"": ("scoring.pixelwise.x__sample_problem__mutmut_13",),
    # issue 23's scoring engine (results/mutation/issue23/)
    "equivalent: a cache bypassed or keyed differently: the value is computed afresh (the same numbers) or "
    "kept under another key that is still unique to it (SceneReference.memo / per_prediction, PixelSet.memo, "
    "the reference score_predictions shares, the MAE shortcut for the scene's own gt and a read-only "
    "prediction)": (
        *(f"scoring.prepare.xǁSceneReferenceǁper_prediction__mutmut_{i}" for i in (1, 2, 5)),
        *(f"scoring.region_metrics.x__mae_fn__mutmut_{i}" for i in (7, 26, 30, 31, 38, 44, 45)),
        *(f"scoring.region_metrics.x__missed_dots_fn__mutmut_{i}" for i in (39, 43, 44)),
        "scoring.region_metrics.x__halfway_of__mutmut_16", "scoring.region_metrics.x__halfway_of__mutmut_17",
        *(f"scoring.region_metrics.x__bump_fn__mutmut_{i}" for i in (33, 39, 40, 53, 54)),
        "scoring.region_metrics.x__backgammon_sample__mutmut_19",
        "scoring.region_metrics.x__backgammon_sample__mutmut_20",
        *(f"scoring.score.x_score_predictions__mutmut_{i}" for i in (1, 12, 19))),
    "equivalent: a shortcut taken or not: when every element is kept, `values[keep]` is `values` (the same "
    "elements in the same order); at scale 1 the upsampling index is the identity; the block size of "
    "PixelSet.values only splits the same rows differently": (
        "scoring.general.x_mse_x100_of__mutmut_9", "scoring.general.x__where__mutmut_1",
        "scoring.general.x_quantile_x100_of__mutmut_21", "scoring.prepare.xǁSceneReferenceǁpixels__mutmut_12",
        "scoring.prepare.xǁSceneReferenceǁpixels__mutmut_15", "scoring.pixels.xǁPixelSetǁvalues__mutmut_1"),
    "equivalent: upsample_index zooms a map whose every column (row) holds the row (column) numbers: zoom "
    "maps each axis on its own, so the number of repeated columns, which of them is read and an integer "
    "arange (exact in zoom's float64) give the same index": (
        *(f"scoring.prepare.x_upsample_index__mutmut_{i}" for i in (14, 16, 17, 19, 32, 34, 35, 37)),),
    "equivalent: read_png gives a label mask as non-negative integers (uint8, uint16, or int32 from a 16-bit "
    "PNG), so the int32 cast is never needed, and made anyway it keeps every label value": (
        *(f"scoring.prepare.x_read_label_mask__mutmut_{i}" for i in (25, 26, 27, 28, 31, 32, 33, 34, 35, 36, 37,
                                                                         38, 39)),),
    "equivalent: False and None are both false (the flag `nearer_foreground`), and a 2-D PixelSet's "
    "shape[+1] is its shape[-1]": (
        "scoring.region_metrics.x_backgammon_thinning__mutmut_4",
        "scoring.region_metrics.x__bg_thinned__mutmut_4", "scoring.pixels.xǁPixelSetǁ__init____mutmut_10"),
    "equivalent: without any (box, label) pair DotLayout.missed returns NaN before it reads the layout's "
    "index, key or dropped count; the candidate pixels only skip labels the lookup tables map to -1 anyway": (
        *(f"scoring.region_metrics.xǁDotLayoutǁof__mutmut_{i}" for i in (44, 45, 47, 58, 60, 61, 63, 66, 67)),),
    "equivalent: the default percentage of quantile_x100_of is 25, so leaving 25 out of _q25_of's call "
    "changes nothing": ("scoring.general.x__q25_of__mutmut_6",),
    "equivalent: MSE's short label is its name ('MSE x100'), so without it the column header is the same; Q25 "
    "is the last metric with an order (4), and 5 keeps it last": (
        "scoring.general.x__mse_metric__mutmut_11", "scoring.general.x__mse_metric__mutmut_24",
        "scoring.general.x__q25_metric__mutmut_47"),
    "equivalent: NumPy's reshape reads a negative size as the one unknown dimension, -2 as -1": (
        *(f"scoring.pixels.xǁPixelErrorsǁof_maps__mutmut_{i}" for i in (23, 30, 41)),
        "scoring.stats.x__signflip_p__mutmut_62"),
    "equivalent: every region BadPix is BadPix(0.07), bad_pix_of's default threshold, so leaving t out of "
    "the call changes nothing": ("scoring.region_metrics.x__bad_pix_pixels__mutmut_6",),
    # issue 31's run (issue31/README.md): the one check of a prediction, the CSV bounds, the gate, pixelwise.py
    "equivalent: disparity_problem halves dh and dw only after refusing odd ones (`not dh % 2 and not dw % 2`), "
    "so `max(dh, dw) / 2` equals `// 2`": ("data.disparity.x_disparity_problem__mutmut_33",),
    "equivalent: `skipped` is an ordered set of scene names (a dict of None): only its keys are read, so the "
    "value stored changes nothing": ("runs.regress.x_check__mutmut_13",),
    "equivalent: json.dumps in make_golden never meets a non-finite number, the only thing `allow_nan` decides "
    "(and allow_nan=None is as false as False): a value that fails math.isfinite is left out of the records, "
    "and every tolerance written has passed check_tolerance and then _tolerance_too_wide, which refuses NaN "
    "and +-inf (`nan < span` is False) with a SpecError before the write (tests/test_gate_mutants.py, "
    "test_make_golden_leaves_out_nonfinite_values)": (
        *(f"runs.regress.x_make_golden__mutmut_{i}" for i in (95, 98, 100)),),
    "equivalent: check reads only `.badness` of the Metric.undefined(...) it builds for a golden metric "
    "lfbench does not know (reachable only with GoldenRecords built by hand: read_golden refuses unknown ids), "
    "and badness depends on `signed` and `higher_is_better` (False for every undefined metric), never on the "
    "id, which Metric's checks read only to word an error that an undefined metric never raises": (
        "runs.regress.x_check__mutmut_59",),
    "equivalent for every caller: the widest line of an empty file (no lines) is compared with max_columns, "
    "and a default of 1 instead of 0 changes the verdict only for max_columns < 1 (no caller passes one; "
    "a CSV table has at least one column)": ("utils.readfile.x_read_csv__mutmut_28",),
    "equivalent: an all-True `keep` selects every pixel, as None does (values[keep] is a copy of the same "
    "values in the same order; every reader of Sample.keep indexes with it or skips it when None), and "
    "Sample's `keep` defaults to None": (
        "scoring.pixelwise.x_kept__mutmut_1", "scoring.pixelwise.x_kept__mutmut_5",
        *(f"scoring.general.x_squared_error__mutmut_{i}" for i in (4, 9))),
    "equivalent: astype(None) is astype(float64), the dtype named (bool values and bincount's int64 counts "
    "become float64 either way)": (
        "scoring.pixelwise.xǁProportionǁpooled_replicates__mutmut_9",
        "scoring.pixelwise.x__pooled_means__mutmut_11"),
    "equivalent: a default that is never used: PixelMetric and OnMaps are called only by Metric.__call__, "
    "Metric.score_pixels and stats' errors-only view, which always pass `toolkit=`": (
        "scoring.pixelwise.xǁPixelMetricǁ__call____mutmut_1", "scoring.pixelwise.xǁOnMapsǁ__call____mutmut_1"),
    "equivalent on POSIX: `getattr(os, NAME, default)`'s default (or its absence) is used only where os lacks "
    "O_NONBLOCK / O_CLOEXEC, which every POSIX Python has": (
        *(f"utils.readfile.x__open__mutmut_{i}" for i in (10, 13, 16, 19, 22, 25)),),
    "equivalent in lfbench: O_CLOEXEC only keeps the descriptor out of a program exec'd while it is open; every "
    "caller of _open closes it before returning and starts no process in between": (
        *(f"utils.readfile.x__open__mutmut_{i}" for i in (17, 23, 24)),),
    "unreachable on Linux: os.open of a folder read-only succeeds (no IsADirectoryError), and fstat's S_ISDIR "
    "check right after refuses it with the same text": (
        *(f"utils.readfile.x__open__mutmut_{i}" for i in (30, 31, 32, 33)),),
    "equivalent: the size of each read (pieces of at most 1 or 2 MiB, at most what is left of max_bytes + 1 or "
    "a little more) changes how many bytes past the cap may be read, never the verdict (total > max_bytes) or "
    "the bytes returned or hashed": (
        *(f"utils.readfile.x_read_bytes__mutmut_{i}" for i in (25, 27, 29, 30)),
        "utils.readfile.x_file_sha256__mutmut_18", "utils.readfile.x_file_sha256__mutmut_19"),
    "equivalent: bytes.decode's default codec is UTF-8, and 'UTF-8' names the same codec as 'utf-8'": (
        "utils.readfile.x_read_text__mutmut_16", "utils.readfile.x_read_text__mutmut_19"),
    # issue 39's two rounds (results/mutation/issue39/README.md): the scorer policy, the dataset files, stats.py,
    # orientation.py and the dataset adapters
    "equivalent: a default that is never used: BadPixels.__call__ and squared_error are called only by "
    "PixelMetric.draw, which always passes `toolkit=`": (
        "scoring.general.xǁBadPixelsǁ__call____mutmut_1", "scoring.general.x_squared_error__mutmut_1"),
    "equivalent: after the field check every field of a pattern is {u}, {v} or {k}, and the complement in "
    "{u, v, k} maps {u, v} <-> {k}, so `f not in pattern` gives the same verdict for every pattern": (
        "data.dataset_file.x_pattern_problem__mutmut_39",),
    "equivalent: the last piece of a split at the last dot is the same for any maxsplit, and with a '.' in the "
    "name `rsplit(\".\", 1)` has exactly two pieces, so [+1] is [-1]": (
        *(f"data.dataset_file.xǁGroundTruthSectionǁcheck_options__mutmut_{i}" for i in (12, 17, 18)),),
    "equivalent: block_groups' mask without dtype=bool: np.nonzero treats any non-zero as True and the shape is "
    "the same (a uint8 mask of 0 / 7 gives the same tiles)": (
        "scoring.stats.x_block_groups__mutmut_7", "scoring.stats.x_block_groups__mutmut_9"),
    "equivalent: _signflip_p's sums without dtype=np.float64: every caller passes float64 (per-pixel or per-tile "
    "differences, bincount's weighted sums); ints would sum exactly anyway": (
        "scoring.stats.x__signflip_p__mutmut_3", "scoring.stats.x__signflip_p__mutmut_5"),
    "equivalent: _signflip_p with no units: itertools.product(repeat=0) is one empty sign vector, so both "
    "branches give the (1, 0) array, and two empty rows have the same mean, 1.0": (
        "scoring.stats.x__signflip_p__mutmut_20", "scoring.stats.x__signflip_p__mutmut_31"),
    "equivalent: `>` for `>=` against `observed - tol`: tol > 0 always (at least 1e-309), so a tie is strictly "
    "above `observed - tol`; they differ only when |flipped| equals `observed - tol` to the last bit": (
        "scoring.stats.x__signflip_p__mutmut_36", "scoring.stats.x__signflip_p__mutmut_81"),
    "equivalent: `(x.size + 8) // 8` bytes per draw reads at most one more byte; unpackbits(count=x.size) keeps "
    "the first x.size bits, fair independent coin flips either way (another stream, the same law of p)": (
        "scoring.stats.x__signflip_p__mutmut_59",),
    "equivalent: astype(None) / dtype=None where the value is float64 anyway: astype(None) is float64 (_loss, "
    "_signflip_p's bits); every registered family's loss_dtype is float64 or None; every caller's bootstrap "
    "replicates are float64 (ints give the same quantiles); read_ci_csv's numbers are Python floats; the "
    "McNemar counts' array divided by an int is true division": (
        "scoring.stats.x__signflip_p__mutmut_64",
        "scoring.stats.x__loss__mutmut_16", "scoring.stats.x__loss__mutmut_58",
        "scoring.stats.x__percentile_ci__mutmut_9", "scoring.stats.x__percentile_ci__mutmut_11",
        "scoring.stats.x_read_ci_csv__mutmut_57", "scoring.stats.x_read_ci_csv__mutmut_59",
        "scoring.stats.x_paired_pixel_test__mutmut_95", "scoring.stats.x_paired_pixel_test__mutmut_97"),
    NAN: (
        *(f"scoring.stats.x_bootstrap_mean_over_scenes__mutmut_{i}" for i in (20, 23, 26, 39, 42)),
        "scoring.stats.x__percentile_ci__mutmut_28", "scoring.stats.x__percentile_ci__mutmut_31",
        *(f"scoring.stats.x_paired_scene_test__mutmut_{i}" for i in (38, 41, 44, 47)),
        *(f"scoring.stats.x_paired_pixel_test__mutmut_{i}" for i in (66, 69, 72, 75)),
        "scoring.stats.x_ci_records__mutmut_36"),
    "equivalent: paired_scene_test with dtype=None for one side: the other side stays float64, so `a - b` is "
    "float64 (two unsigned sides, where `a - b` would wrap, are tested)": (
        *(f"scoring.stats.x_paired_scene_test__mutmut_{i}" for i in (5, 7, 10, 12)),),
    "equivalent: a toolkit flag None or left to its default, which is False (None is falsy)": (
        "scoring.stats.x__loss__mutmut_69", "scoring.stats.x__loss__mutmut_71",
        "scoring.stats.x_paired_pixel_test__mutmut_8", "scoring.stats.x_paired_pixel_test__mutmut_18"),
    "equivalent: the np.errstate entry surrounds operations that raise no floating-point warning (_loss's "
    "np.abs and np.where; the registered draws compare and square: NaN, inf and an overflowing square run "
    "under `-W error`)": (
        "scoring.stats.x__loss__mutmut_13", "scoring.stats.x__loss__mutmut_59", "scoring.stats.x__loss__mutmut_61"),
    "equivalent: `loss[None] = ...` assigns the whole array, as `loss[:]` does": ("scoring.stats.x__loss__mutmut_80",),
    COPY: (*(f"scoring.stats.xǁScoredErrorsǁfrom_prepared__mutmut_{i}" for i in (26, 28, 29)),),
    "equivalent: paired_pixel_test's measure default \"ABS\" (_loss lower-cases the measure) and binomtest "
    "without 0.5 (scipy's default)": (
        "scoring.stats.x_paired_pixel_test__mutmut_2", "scoring.stats.x_paired_pixel_test__mutmut_126"),
    "equivalent: `worse - better == 0` for `worse + better == 0`: with worse = better > 0 the exact two-sided "
    "binomial p is 1.0 as well": ("scoring.stats.x_paired_pixel_test__mutmut_117",),
    "equivalent: np.bincount without minlength (the tile ids from np.unique's inverse cover 0 .. n_groups - 1, "
    "so the length is n_groups) and integer tile sizes (the same ratio)": (
        *(f"scoring.stats.x_paired_pixel_test__mutmut_{i}" for i in (163, 165, 169)),),
    "equivalent: np.array(None) for no resample of no pixel: _percentile_ci reads it as one NaN and drops it, "
    "the same NaN bounds": ("scoring.stats.x_bootstrap_metric__mutmut_57",),
    "equivalent: ci_records' itertuples(index=None) / index=True (a leading Index field; the fields are read by "
    "name) and groupby(sort=None) (pandas reads it as False: the results' order, tested)": (
        *(f"scoring.stats.x_ci_records__mutmut_{i}" for i in (19, 20, 94)),),
    "equivalent: warp_error's centre view without dtype=float32: its only caller (check-dataset) passes "
    "Scene.gray_views(), float32; float64 views give the same number to float32 rounding (< 1e-7 relative; "
    "the 1.25 ratio decides)": (
        "data.orientation.x_warp_error__mutmut_19", "data.orientation.x_warp_error__mutmut_21"),
    "equivalent: warp_error's du and dv without dtype=float32: int64 tensors of the view steps; `du * d` with a "
    "float32 d promotes to float32 and small integers are exact in float32: the same sampling positions bit for "
    "bit": (*(f"data.orientation.x_warp_error__mutmut_{i}" for i in (95, 97, 101, 103)),),
    "equivalent: grid_sample without mode=\"bilinear\" / padding_mode=\"zeros\": those are torch's defaults": (
        "data.orientation.x_warp_error__mutmut_171", "data.orientation.x_warp_error__mutmut_172"),
    "equivalent: warp_error's `.sum(dtype=None)` (a float32 sum of the absolute errors): torch's float32 "
    "reduction is cascaded, ~1e-7 relative at any size, far below any decision (ratio 1.25)": (
        "data.orientation.x_warp_error__mutmut_183",),
    "equivalent: `break` for `continue` on a transposed reading of a non-square grid: the four transposed "
    "readings are the last four of ORIENTATIONS, so stopping at the first skips exactly them": (
        "data.orientation.x_distinct_readings__mutmut_12",),
    "equivalent: read_dataset_spec's `Table(raw, None, ...)` for `Table(raw, \"\", ...)`: the top table's "
    "`where` is only tested for truth, and None and \"\" are both false": (
        "data.generic.x_read_dataset_spec__mutmut_12", "data.generic.x_read_dataset_spec__mutmut_28"),
    "equivalent: read_dataset_spec's `Table(raw, \"\", None)` (no source): the SpecError then carries no path, "
    "the removeprefix has nothing to remove, and the DataError names the file once: the same line": (
        "data.generic.x_read_dataset_spec__mutmut_13", "data.generic.x_read_dataset_spec__mutmut_29"),
    "equivalent: `top.used = {...}` for `|=`: a new Table's `used` is empty": (
        "data.generic.x_read_dataset_spec__mutmut_19",),
    "equivalent: Benchmark(...) without `splits={}`: its default is an empty dict": (
        "data.generic.xǁGenericDatasetǁopen__mutmut_32", "data.urbanlf.xǁUrbanLFSynǁopen__mutmut_25"),
    "equivalent: `getattr(dataset, \"__module__\", default)` with the default None, dropped or \"XXXX\": every "
    "class has a __module__, so the default is never read": (
        *(f"data.dataset.x__plugin__mutmut_{i}" for i in (5, 8, 11)),),
    # the third round (issue 31's changes outside scoring: results/mutation/issue39/README.md)
    "equivalent: a codec name in another case (\"UTF-8\" for \"utf-8\"): Python's codec lookup ignores case": (
        "utils.atomic.x_write_text__mutmut_12", "method.checkpoint.x_sniff__mutmut_59",
        "utils.executor.x_run_marked__mutmut_13", "utils.executor.xǁProcessPoolǁ_died__mutmut_16",
        "utils.outputs.x__read_book__mutmut_30"),
    "equivalent: write_bytes' or checkpoint.save's atomic_open(path) without \"wb\": atomic_open's mode defaults "
    "to \"wb\"": (
        "utils.atomic.x_write_bytes__mutmut_4", "training.checkpoint.x_save__mutmut_4"),
    "equivalent: write_text's `newline=None` or no newline: on POSIX, where lfbench runs (fork, symbolic links, "
    "SIGKILL), a written '\\n' is '\\n' (os.linesep)": (
        "utils.atomic.x_write_text__mutmut_4", "utils.atomic.x_write_text__mutmut_8"),
    "equivalent: check_output_file's `resolve(strict=None)`: None is false, as strict=False": (
        "utils.outputs.x_check_output_file__mutmut_5",),
    "equivalent: read_marker's `what` (None, dropped, another text) only words a DataError that read_marker "
    "catches (an unreadable marker is no marker): never shown": (
        *(f"ablation.cell.x_read_marker__mutmut_{i}" for i in (3, 5, 8, 9)),),
    "equivalent: symlink_to's `target_is_directory` (None, dropped, False) matters only on Windows; POSIX makes "
    "the same link": (
        *(f"ablation.cell.x_link_data_folder__mutmut_{i}" for i in (12, 14, 19)),),
    "equivalent: _is_name's `c in \"XX_-.XX\"`: X is alphanumeric, so the set of characters allowed is the same": (
        "method.checkpoint.x__is_name__mutmut_10",),
    # the full run's region-metric survivors (tests/test_region_mutants_full.py kills the others)
    "equivalent: the ground truth's bumpiness support computed under `toolkit` too: _bump_mean reads it only "
    "without `toolkit` (the toolkit's rule leaves every non-finite value out), so no number changes": (
        "scoring.region_metrics.x_bumpiness_x100__mutmut_25", "scoring.region_metrics.x__bump_fn__mutmut_47"),
    "equivalent: np.clip(cos, -1, 1, out=cos) or into a new array: the same values, and cos is "
    "angular_error_deg's own temporary": (
        "scoring.region_metrics.x_angular_error_deg__mutmut_22",
        "scoring.region_metrics.x_angular_error_deg__mutmut_26"),
    "equivalent: _present's `1 << label` in np.left_shift's own result type instead of uint32: uint32 for "
    "unsigned labels of up to 32 bits and bool, int64 or uint64 for signed or 64-bit ones; every type holds "
    "1 << 31 exactly and this branch sees labels 0..31 only (the labels are integers: DotLayout indexes its "
    "lookup tables with them)": (
        "scoring.region_metrics.x__present__mutmut_27", "scoring.region_metrics.x__present__mutmut_31"),
    # the fourth round (the rest of outputs.py, cell.py, executor.py, training/checkpoint.py)
    "equivalent: the `what` of a read whose DataError is caught and never shown (time_cell's read of an old "
    "timing.json: suppressed, the timing is made again; _manifest_lists: any DataError is False; _read_book's "
    "parse_json, path and what: its DataError is replaced by _read_book's own refusal naming the file)": (
        *(f"ablation.cell.x_time_cell__mutmut_{i}" for i in (37, 39, 40, 41)),
        *(f"utils.outputs.x__manifest_lists__mutmut_{i}" for i in (3, 6, 7)),
        *(f"utils.outputs.x__read_book__mutmut_{i}" for i in (23, 24, 26, 27)),),
    "equivalent: rng_state's torch.tensor(internal) without dtype=torch.int64: a tuple of Python ints is int64 by "
    "torch's own inference": (
        "training.checkpoint.x_rng_state__mutmut_9", "training.checkpoint.x_rng_state__mutmut_11"),
    "equivalent: set_rng_state's keys `.astype(None)` (float64) for `.astype(np.uint32)`: every key is below 2^32, "
    "exact in float64, and numpy's set_state casts the key array to uint32 itself": (
        "training.checkpoint.x_set_rng_state__mutmut_12",),
    "equivalent: evaluate_weights' Maps() without MAPS: cell.MAPS and Maps' default folder "
    "(reports.maps.MAPS_DIR) are both \"maps\"": (
        "ablation.cell.x_evaluate_weights__mutmut_28",),
    "equivalent: ProcessPool.map's inline branch gives InProcess other options, log or threads: InProcess.map "
    "uses none of them (it runs fn in order and calls on_start / on_done)": (
        *(f"utils.executor.xǁProcessPoolǁmap__mutmut_{i}" for i in (7, 16, 17, 19)),),
    "equivalent: _alive's pid as `split(\".\")[0]` or `split(\".\", 2)[0]`: the first field is the same whatever "
    "the number of splits": (
        "utils.outputs.x__alive__mutmut_6", "utils.outputs.x__alive__mutmut_9"),
    # the full run's late functions (tests/test_scoring_mutants_late.py kills the others)
    "equivalent: score_scene's reference.prepare(pred, res, ...) with the source None or left to its default: "
    "score_scene aligned and checked the prediction under its source before (reference.align), and prepare's "
    "own check of that aligned map finds nothing, so the source is never written": (
        "scoring.score.x_score_scene__mutmut_54", "scoring.score.x_score_scene__mutmut_57"),
    "equivalent: align_prediction's `kind in \"XXfiuXX\"`: no NumPy dtype kind is X, so the kinds accepted are "
    "the same; np.full(shape, None, dtype=float32) is NaN, as np.nan": (
        "scoring.prepare.x_align_prediction__mutmut_17", "scoring.prepare.x_align_prediction__mutmut_35"),
    "equivalent: PixelSet.values' guard with `>=` (at equality the columns fit: `take` reads the same values as "
    "the repeats, only slower) or `pred.shape[+1]` (the prediction is 2-D: index 1 is index -1)": (
        "scoring.pixels.xǁPixelSetǁvalues__mutmut_23", "scoring.pixels.xǁPixelSetǁvalues__mutmut_24"),
    "equivalent: a sample's fast path made never taken (`... and False`): when every flag is True, kept() and "
    "np.where give a Sample of the same values with keep None; the test only saves computing the flags": (
        "scoring.general.x_abs_error_x100__mutmut_15", "scoring.general.x_abs_error_x100__mutmut_23",
        "scoring.general.xǁBadPixelsǁ__call____mutmut_28"),
    "equivalent: _own's `getattr(fn, \"__module__\", default)` with the default None or \"XXXX\" for \"\": a "
    "callable without a __module__ is not lfbench's whatever text stands for it (\"None\", \"XXXX\" and \"\" are not "
    "\"lfbench\")": (
        "scoring.pixelwise.x__own__mutmut_5", "scoring.pixelwise.x__own__mutmut_11"),
    "equivalent: Metric.__post_init__'s list of scene aggregates joined by another separator: SCENE_AGGREGATES "
    "holds one name, and one name joined has no separator": ("scoring.base.xǁMetricǁ__post_init____mutmut_16",),
    "equivalent: Metric.__post_init__'s `isnan(low) and isnan(high)` for `or`: a NaN bound makes `not low < high` "
    "true by itself, so a range with one NaN is refused either way": (
        "scoring.base.xǁMetricǁ__post_init____mutmut_19",),
    "equivalent: MSE's short_label None or left out: a metric's label falls back to its name, which is the same "
    "text (\"MSE x100\")": ("scoring.general.x__mse_metric__mutmut_10", "scoring.general.x__mse_metric__mutmut_21"),
    "equivalent: _ordinal's teens from 11 (`11 <=`, `10 <`) or to 19 (`< 20`): 10 and 20 end in 0, whose suffix is "
    "\"th\" either way": (
        "scoring.general.x__ordinal__mutmut_10", "scoring.general.x__ordinal__mutmut_11",
        "scoring.general.x__ordinal__mutmut_14"),
    # the full run's timeouts run again single-threaded (tests/test_mutants_hidden_by_timeouts.py kills the others)
    "equivalent: npy_bytes' np.save with allow_pickle None, True or its default: the array was made float32 just "
    "before, and a numeric array is written without a pickle whatever the flag": (
        *(f"data.urbanlf.x_npy_bytes__mutmut_{i}" for i in (4, 7, 12)),),
    "equivalent: warp_error's torch.meshgrid with indexing None or left out: torch's default is \"ij\" (it only "
    "warns that the default may change)": (
        "data.orientation.x_warp_error__mutmut_31", "data.orientation.x_warp_error__mutmut_34"),
    "equivalent: _present's loop with step 1 instead of the chunk: the windows [start, start + chunk) overlap but "
    "cover the same labels, so the same bits are set (only slower: the full run's timeouts)": (
        "scoring.region_metrics.x__present__mutmut_22",),
}

# Survivors that are NOT equivalent: a test could tell them apart, but none in the fast suite can (each says why).
# They are reported in the table under their reason, which begins with NOT_KILLED, and counted apart; they do not
# fail the run, since they are known and written down, but they are never called equivalent.
NOT_KILLED = "not killed (known, not equivalent): "
KNOWN_NOT_KILLED: dict[str, tuple[str, ...]] = {
}

_FIELDS = re.compile(r"\b(name|description|vmin|vmax|cmap)=(f?\"[^\"]*\"|[^,)\n]*)\s*,?")


def _changed(diff: str) -> tuple[str, str]:
    minus = " ".join(line[1:] for line in diff.splitlines() if line.startswith("-"))
    plus = " ".join(line[1:] for line in diff.splitlines() if line.startswith("+"))
    return minus, plus


def _squash(text: str) -> str:
    return re.sub(r"\s+", "", text)


def reason_of(name: str, diff: str) -> str | None:
    short = name.removeprefix(_SEEN_AT)
    for reason, names in (*REASONS.items(), *KNOWN_NOT_KILLED.items()):
        if short in names:
            return reason
    minus, plus = _changed(diff)
    if minus and _squash(_FIELDS.sub("", minus)) == _squash(_FIELDS.sub("", plus)):
        return PRESENTATION
    if minus and _squash(re.sub(r"copy=\w+,?", "", minus)) == _squash(re.sub(r"copy=\w+,?", "", plus)):
        return COPY
    if minus and plus.replace('"NAN"', '"nan"') == minus:
        return NAN
    return None


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mutants", type=Path, default=ROOT / "mutants")
    parser.add_argument("--recheck", type=Path, nargs="+", required=True,
                        help="recheck_import_time.py's reports (a later one's verdict wins)")
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()
    verdicts = {}
    for report in args.recheck:
        verdicts.update(json.loads(report.read_text(encoding="utf-8"))["verdicts"])
    rows, unexplained = [], []
    for name, _, diff in survivors(args.mutants, (SURVIVED,)):
        if verdicts.get(name) == "killed":
            continue
        reason = reason_of(name, diff)
        if reason is None:
            unexplained.append(name)
        minus, plus = _changed(diff)
        change = f"`{' '.join(minus.split())[:90]}` -> `{' '.join(plus.split())[:90]}`".replace("|", "\\|")
        rows.append(f"| {name.removeprefix(_SEEN_AT)} | {change} | {reason or 'UNEXPLAINED'} |")
    counts: dict[str, int] = {}
    for row in rows:
        reason = row.rsplit(" | ", 1)[1].rstrip(" |")
        counts[reason] = counts.get(reason, 0) + 1
    summary = "\n".join(f"- {n}: {reason}" for reason, n in sorted(counts.items(), key=lambda kv: -kv[1]))
    text = (f"# Surviving mutants and why ({len(rows)})\n\nWritten by `python tools/mutation/classify.py` "
            f"(see README.md).\n\n{summary}\n\n| mutant | change | reason |\n| --- | --- | --- |\n"
            + "\n".join(rows) + "\n")
    args.out.write_text(text, encoding="utf-8")
    for name in unexplained:
        print(f"UNEXPLAINED {name}")
    known = sum(n for reason, n in counts.items() if reason.startswith(NOT_KILLED))
    print(f"{len(rows)} survivors, {known} not killed (known, not equivalent), {len(unexplained)} unexplained")
    return 1 if unexplained else 0


if __name__ == "__main__":
    raise SystemExit(main())
