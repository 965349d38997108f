"""How BadPix compares and what a non-finite value counts as: a dataset protocol's *scorer* (its
``DatasetProtocol.scorer``, recorded in ``meta.scoring.scorer`` when it is not lfbench's).

- ``lfbench`` (HCI's, and the TOML format's default): BadPix counts |error| > t as bad, a non-finite
  prediction is bad, pixels of non-finite ground truth are not scored, MSE leaves non-finite errors out
  (docs/benchmark-rules.md); ``--toolkit-nonfinite`` switches to the HCI toolkit's non-finite rule.
- ``paper-author``: the one public script that scores UrbanLF-Syn, by the SubFocal paper's first author
  (github.com/chaowentao/ContextNet, ``evalution_urban.py``; his github.com/chaowentao/SubFocal
  ``evalution.py`` scores HCI the same way): BadPix counts |error| >= t as bad over every pixel inside the
  border, so a NaN error (``NaN >= t`` is False) counts as good and an infinite one as bad; MSE x100 is 100 x
  the mean of the squared errors over every pixel, so one NaN makes it NaN. docs/datasets.md cites it.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["LFBENCH", "PAPER_AUTHOR", "SCORERS", "ScorerPolicy", "scorer"]


@dataclass(frozen=True)
class ScorerPolicy:
    """``inclusive``: BadPix's bad pixels are |error| >= t (else > t); ``nan_good``: every pixel inside the border
    is scored, as computed (NaN good in BadPix, NaN in MSE), instead of lfbench's non-finite rule."""

    name: str
    inclusive: bool
    nan_good: bool
    source: str


LFBENCH = ScorerPolicy("lfbench", inclusive=False, nan_good=False,
                       source="the HCI toolkit's comparison, lfbench's non-finite rule (docs/benchmark-rules.md)")
PAPER_AUTHOR = ScorerPolicy("paper-author", inclusive=True, nan_good=True,
                            source="github.com/chaowentao/ContextNet evalution_urban.py (the SubFocal paper's "
                                   "first author's UrbanLF-Syn scorer)")
SCORERS: dict[str, ScorerPolicy] = {p.name: p for p in (LFBENCH, PAPER_AUTHOR)}


def scorer(name: str) -> ScorerPolicy:
    """The policy of ``name``; ValueError naming the choices otherwise."""
    if name not in SCORERS:
        raise ValueError(f"unknown scorer {name!r}; choose from {', '.join(SCORERS)}")
    return SCORERS[name]
