"""What a method is: something that turns a light field into a disparity map."""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from lfbench.data.disparity import EVALUATION_BORDER_PX, check_disparity
from lfbench.data.scene import LightField
from lfbench.method.params import format_spec
from lfbench.utils.errors import DataError
from lfbench.utils.readfile import file_sha256


@dataclass
class Prediction:
    """A method's output for one light field.

    disparity: (H, W) float32, px per view step. distribution: (D, H, W) float32 probabilities over
    ``disparity_values`` (D,) when the method has one; uncertainty: (H, W) float32 (larger = less
    sure). runtime_s: wall time of the prediction in s (a precomputed result carries its own).
    """

    disparity: np.ndarray
    distribution: np.ndarray | None = None
    disparity_values: np.ndarray | None = None
    uncertainty: np.ndarray | None = None
    runtime_s: float | None = None


class Method:
    """Base class of registered methods: the contract every method follows.

    A method turns a light field into a :class:`Prediction`. Subclasses implement :meth:`predict`
    and may override the other hooks below; each has a default that fits a method without it.
    Parameters are keyword arguments of ``__init__``, typed and documented with ``typing.Annotated``
    (``radius: Annotated[int, "aggregation radius in px"] = 3``; see lfbench.method.params and
    ``lfbench methods``).

    The registry creates methods (``create``, ``create_from_spec``) and sets :attr:`name` and
    :attr:`params` once, after ``__init__``; they are read-only afterwards.
    """

    #: Parameters naming a file whose content, not location, identifies the method (e.g. ``weights``): the
    #: label carries ``sha256:<first 12 hex digits>`` of the file instead of its path, so that results keep
    #: their keys when the file moves (the path is kept in :meth:`provenance`).
    content_params: ClassVar[tuple[str, ...]] = ()
    #: True for a method that knows the answer (the ``gt`` oracle): reports show it as a reference line, never
    #: as a competitor (no rank, not in pairwise comparisons); runs record it in ``results.meta["references"]``.
    oracle: ClassVar[bool] = False

    _name: str = ""
    _params: dict[str, Any] = {}  # replaced, never mutated
    _bound: bool = False
    _label: str | None = None  # a label the user gave (--label), or the computed one, cached
    _given_label: bool = False

    def __init__(self, **params: Any) -> None:
        """``params``: the parameters this instance was configured with, used as :attr:`params` of a
        method made without the registry (the registry replaces them with the ones it was given)."""
        self._params = dict(params)

    # -- identity (set by the registry) ----------------------------------------------------------

    @property
    def name(self) -> str:
        """The registered name ("" for a method made without the registry)."""
        return self._name

    @property
    def params(self) -> dict[str, Any]:
        """The parameters it was created with (a copy), as given: defaults are not listed."""
        return dict(self._params)

    def _bind(self, name: str, params: dict[str, Any]) -> None:
        """Record how the registry made this method; a second call is an error (set once)."""
        if self._bound:
            raise RuntimeError(f"method {self.label!r} is already registered; name and params are set once")
        self._name, self._params, self._bound = name, dict(params), True
        if not self._given_label:
            self._label = None

    @property
    def label(self) -> str:
        """How results name this method: the canonical spec ``name:key=value,...``, with the content hash of
        each file named by a :attr:`content_params` parameter in place of its path; or the label the user
        gave (:meth:`with_label`)."""
        if self._label is None:
            self._label = format_spec(self.name, {k: self._content_id(k, v) if k in self.content_params else v
                                                  for k, v in self.params.items()})
        return self._label

    def check_content(self, key: str, path: Path) -> None:
        """Raise DataError naming ``path`` when the file of the :attr:`content_params` parameter ``key`` is not
        one this method can use, from bounded reads only: called before the file is hashed for the method's
        label (a network's weights: a torch checkpoint of bounded size). Default: no check."""

    def _content_id(self, key: str, value: Any) -> Any:
        """:func:`content_id` of a :attr:`content_params` value, after :meth:`check_content` of its file."""
        if isinstance(value, str | Path) and Path(value).expanduser().is_file():
            self.check_content(key, Path(value).expanduser())
        return content_id(value)

    @property
    def spec(self) -> str:
        """The spec this method was made from, as given (paths as written)."""
        return format_spec(self.name, self.params)

    def with_label(self, label: str) -> Method:
        """Name this method's results ``label`` instead of its computed label (e.g. ``--label``); set once."""
        if self._given_label:
            raise RuntimeError(f"method {self.label!r} has a label already; it is set once")
        self._label, self._given_label = str(label), True
        return self

    def provenance(self) -> dict[str, Any]:
        """Where the method came from, beside its label in results: the spec as given and, for each file of
        :attr:`content_params`, its absolute path and SHA-256."""
        out: dict[str, Any] = {"spec": self.spec}
        for key in self.content_params:
            value = self.params.get(key, getattr(self, key, None))
            if isinstance(value, str | Path) and Path(value).expanduser().is_file():
                path = Path(value).expanduser().resolve()
                self.check_content(key, path)
                out[key] = {"path": str(path), "sha256": file_sha256(path, key)}
        return out

    # -- hooks -----------------------------------------------------------------------------------

    def predict(self, lf: LightField) -> Prediction:
        """The prediction for ``lf`` (required): disparity (H, W) in px per view step, optionally a
        distribution and an uncertainty map. Raise DataError for a light field it cannot handle."""
        raise NotImplementedError(f"{type(self).__name__} does not implement predict()")

    def available_for(self, lf: LightField) -> str | None:
        """None if the method can run on ``lf``, else a one-line reason (e.g. no stored map, no weights):
        runs skip the method on that scene and say why. Default: always available."""
        return None

    def describe_variant(self) -> dict[str, Any]:
        """Facts about this configured variant beyond its parameters (e.g. trainable parameters, the
        weights it loads), printed by ``lfbench info``. Default: none."""
        return {}

    def offline_variants(self) -> list[dict[str, Any]]:
        """Parameter sets (beyond the defaults this instance has) under which the method runs with what
        is installed, no download: e.g. ``[{"width": 16}]``, the architecture of shipped weights. The demo
        and golden.py run these. Called on an instance made with the defaults. Default: ``[]`` (the
        defaults themselves run)."""
        return []

    def to(self, device: str) -> Method:
        """Run on ``device`` (``cpu``, ``cuda``, ``cuda:1``): a method with a network moves it there.
        Default (a method without one): runs where it is and returns itself."""
        return self

    # -- running ---------------------------------------------------------------------------------

    def run(self, lf: LightField, *, max_crop: int = EVALUATION_BORDER_PX) -> Prediction:
        """predict() with the wall time recorded (unless the prediction carries its own runtime) and the
        disparity checked and made float32 (lfbench.data.disparity.check_disparity: real floating values, the
        light field's size or a symmetric crop of at most ``max_crop`` px per side; DataError naming the method
        and the light field otherwise). Not a hook: runners call this."""
        start = time.perf_counter()
        pred = self.predict(lf)
        elapsed = time.perf_counter() - start
        source = f"{self.label} on {getattr(lf, 'name', 'the light field')}"
        if not isinstance(pred, Prediction):
            raise DataError(f"{source}: predict() returned a {type(pred).__name__}, not a Prediction")
        if pred.runtime_s is None:
            pred.runtime_s = elapsed
        pred.disparity = check_disparity(pred.disparity, lf.spatial_size, source, max_crop=max_crop)
        return pred


def content_id(value: Any) -> Any:
    """``sha256:<12 hex digits>`` of the file ``value`` names, when it names a regular file; else ``value``."""
    if isinstance(value, str | Path) and Path(value).expanduser().is_file():
        return "sha256:" + file_sha256(Path(value).expanduser(), "file")[:12]
    return value


HOOKS = ("predict", "available_for", "describe_variant", "offline_variants", "to")


def overrides(cls: type, hook: str) -> bool:
    """Whether a Method subclass implements ``hook`` itself (rather than inheriting the default)."""
    return getattr(cls, hook, None) is not getattr(Method, hook)


__all__ = ["Method", "Prediction", "HOOKS", "overrides", "content_id"]
