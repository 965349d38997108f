"""Registered methods ``subfocal`` (Chao et al., TCI 2023) and its variant ``lfattnet`` (the baseline:
the same class registered with interval 1 as its default).

SubFocal runs on lfbench's generic network method (lfbench.method.network_method: weights, device,
precision, the weights' content in its label) and adds what is its own: the shipped weights, tiles
planned from a memory budget, TF32 on request, and ``lfbench info`` facts.

Weights come from a checkpoint (``{"state_dict", "config", ...}``, e.g. from ``lfbench train`` or
``lfbench convert-keras``); its stored config decides the architecture, and an explicitly given
parameter that contradicts it is a SpecError. Without ``weights``, the variant's parameters decide
the architecture (default: the paper's, 5,055,329 trainable parameters) and the shipped checkpoint
(methods/weights/<variant>_small.pt, trained on CPU by lfbench itself) is used when it has exactly that
architecture, e.g. ``subfocal:width=16``; otherwise the method is unavailable (never random weights).

Light at import: torch and the network are imported when a method is made.
"""

from __future__ import annotations

import inspect
from pathlib import Path
from typing import Annotated, Literal

from lfbench_methods.subfocal.trainable import LFAttNetTrainable, SubFocalTrainable  # noqa: F401 (registers them)

from lfbench.data.scene import LightField
from lfbench.method.base import Method, Prediction
from lfbench.method.network_method import NetworkMethod
from lfbench.method.params import Range
from lfbench.method.registry import REGISTRY, register_method
from lfbench.method.trainable import get_trainable
from lfbench.utils.errors import DataError, SpecError
from lfbench.utils.hardware import DEVICE_HELP

WEIGHTS_DIR = Path(__file__).resolve().parent.parent / "weights"
PAPER_WIDTH = 150
_ARCH_KEYS = ("d_min", "d_max", "interval", "interpolation", "width", "attention")

LFATTNET_DOC = "LFattNet (Tsai et al., AAAI 2020), SubFocal's baseline: the same network at integer disparities."
LFATTNET_HELP = {
    "weights": "checkpoint .pt (lfbench train / convert-keras --interval 1); default: a shipped checkpoint of the "
               "configured architecture, if any",
    "interval": "disparity step of the cost volume in px (LFattNet 1)",
}


@register_method("lfattnet", defaults={"interval": 1.0}, doc=LFATTNET_DOC, help=LFATTNET_HELP)
@register_method("subfocal")
class SubFocal(NetworkMethod):
    """SubFocal (Chao et al., TCI 2023): sub-pixel cost volume, channel attention, 3D aggregation.

    The uncertainty output is the standard deviation (px) of the predicted disparity distribution.
    """

    network = "subfocal"
    WEIGHTS_DIR: Path = WEIGHTS_DIR  # the shipped checkpoints: <variant>_small.pt

    def __init__(
        self,
        weights: Annotated[Path | None, "checkpoint .pt (lfbench train / convert-keras); default: the shipped "
                                        "CPU-trained checkpoint when the configured architecture is its own (see "
                                        "`lfbench info subfocal`)"] = None,
        interval: Annotated[float, "disparity step of the cost volume in px (paper 0.5; 1, 0.25, 0.1 or any)"] = 0.5,
        interpolation: Annotated[Literal["nearest", "bilinear", "phase"],
                                 "sub-pixel shift of the features: nearest, bilinear (paper) or phase (Fourier)"]
        = "bilinear",
        d_min: Annotated[float, "smallest candidate disparity in px"] = -4.0,
        d_max: Annotated[float, "largest candidate disparity in px"] = 4.0,
        width: Annotated[int | None, "channels of the 3D aggregation (paper 150; with weights=..., the "
                                     "checkpoint's)"] = None,
        attention: Annotated[bool, "channel attention over the views on/off"] = True,
        tile: Annotated[int, "inference tile size in px (0 = from max_memory_gb; exact, with a 9 px halo)",
                        Range(0)] = 0,
        precision: Annotated[Literal["fp32", "bf16"], "fp32, or bf16 autocast for the 3D aggregation"] = "fp32",
        threads: Annotated[int, "torch CPU threads (0 = all cores)", Range(0)] = 0,
        max_memory_gb: Annotated[float, "memory budget of inference in GB (decides the tile size when tile=0); on "
                                        "CUDA at most the GPU's free memory, which is the budget when this is not "
                                        "given"] = 4.0,
        device: Annotated[str, DEVICE_HELP] = "auto",
        tf32: Annotated[bool, "allow TF32 in CUDA fp32 convolutions and matmuls (default off: IEEE fp32)"] = False,
    ) -> None:
        from lfbench_methods.subfocal.network import check_config, network_params

        from lfbench.utils.hardware import require_bf16, resolve_device

        values = {"weights": weights, "interval": interval, "interpolation": interpolation, "d_min": d_min,
                  "d_max": d_max, "width": width, "attention": attention, "tile": tile, "precision": precision,
                  "threads": threads, "max_memory_gb": max_memory_gb, "device": device, "tf32": tf32}
        defaults = _signature_defaults()
        Method.__init__(self, **{k: v for k, v in values.items() if v != defaults[k]})
        check_config(d_min, d_max, interval, interpolation)  # the network's checks (width: ours, None allowed)
        if precision not in ("fp32", "bf16"):
            raise ValueError(f"precision must be fp32 or bf16, got {precision!r}")
        if width is not None and (problem := network_params()["width"].problem(width)):
            raise ValueError(f"width: {problem}")  # the network's declared Range
        if tile < 0 or threads < 0 or not 0 < max_memory_gb < float("inf"):
            raise ValueError("tile and threads must be >= 0 and max_memory_gb a finite number > 0")
        self.trainable = get_trainable("subfocal")
        self.weights = None if weights is None else Path(weights).expanduser()
        self.device = resolve_device(device)  # SpecError for a device this machine lacks
        if precision == "bf16":
            require_bf16(self.device)  # one line, before any work (an AVX2-only CPU cannot run it)
        self.precision, self.threads, self.tile = precision, threads, tile
        self.values = values
        self._net = None

    # -- configuration ----------------------------------------------------------------------

    @property
    def variant(self) -> str:
        """The registered variant (``subfocal`` or ``lfattnet``; ``subfocal`` when made without the registry)."""
        return self.name or "subfocal"

    @property
    def shipped_weights(self) -> Path:
        """The checkpoint shipped for this variant (it may not exist)."""
        return self.WEIGHTS_DIR / f"{self.variant}_small.pt"

    @property
    def weights_path(self) -> Path | None:
        """The checkpoint to load: the one given, else the shipped one if it has this variant's
        architecture, else None."""
        if self.weights is not None:
            return self.weights
        shipped = self.shipped_weights
        if shipped.is_file() and not self._differences(self._configured(), _stored_config(shipped)):
            return shipped
        return None

    def explicit_arch(self) -> dict:
        """Parameters the user gave (the registry records them in ``params``)."""
        return {k: self.values[k] for k in self.params if k in _ARCH_KEYS}

    def _configured(self, values: dict | None = None) -> dict:
        """The architecture from the parameters alone (width: the paper's 150 unless given)."""
        return _architecture(self.values if values is None else values)

    @classmethod
    def range_from_weights(cls, info, params: dict) -> bool:
        """Whether the weights this spec would load fix the disparity grid (d_min, d_max, interval are part of
        the checkpoint's config: the network was trained on that grid), so that a dataset's disparity range
        must not be applied (lfbench.data.dataset.method_range_params): ``weights=`` given, or the variant's
        shipped checkpoint has the architecture of the spec's parameters."""
        if params.get("weights") is not None:
            return True
        shipped = cls.WEIGHTS_DIR / f"{info.name}_small.pt"
        if not shipped.is_file():
            return False
        values = {**{k: p.default for k, p in info.params.items()}, **params}
        return not cls._differences(_architecture(values), _stored_config(shipped))

    @staticmethod
    def _differences(ours: dict, config: dict) -> list[str]:
        """Entries of ``ours`` that ``config`` contradicts, as ``key=ours (checkpoint: theirs)``."""
        out = []
        for key, value in ours.items():
            stored = config.get(key)
            if isinstance(value, float) and isinstance(stored, (int, float)) and not isinstance(stored, bool):
                same = abs(float(stored) - value) < 1e-9
            else:
                same = stored == value
            if not same:
                out.append(f"{key}={value} (checkpoint: {stored})")
        return out

    def check_config(self, config: dict) -> dict:
        """The checkpoint's config, after checking explicit parameters against it (SpecError)."""
        conflicts = self._differences(self.explicit_arch(), config)
        if conflicts:
            raise SpecError(f"{self.variant}: {', '.join(conflicts)} conflicts with the checkpoint "
                            f"{self.weights_path}; leave it out to use the checkpoint's")
        return config

    def offline_variants(self) -> list[dict]:
        """Parameter sets that run with no download: the shipped checkpoint's architecture, as the
        parameters that differ from the variant's defaults (e.g. ``{"width": 16}``). Empty if none is shipped."""
        shipped = self.shipped_weights
        if not shipped.is_file():
            return []
        stored = _stored_config(shipped)
        defaults = self._configured(self._variant_defaults())
        return [{k: stored[k] for k in _ARCH_KEYS if k in stored and stored[k] != defaults[k]}]

    def _variant_defaults(self) -> dict:
        """The parameter defaults of this variant (the registry's, else the signature's)."""
        try:
            return {k: p.default for k, p in REGISTRY.info(self.variant).params.items()}
        except SpecError:
            return _signature_defaults()

    def missing_reason(self) -> str | None:
        p = self.weights_path
        if p is None:
            hint = ""
            variants = self.offline_variants()
            if variants:
                spec = ",".join(f"{k}={v}" for k, v in variants[0].items())
                hint = f", or run the shipped CPU-trained model: {self.variant}:{spec}"
            return ("no weights for this configuration: give weights=CHECKPOINT.pt (lfbench train or "
                    f"lfbench convert-keras){hint}")
        return super().missing_reason()

    def describe_variant(self) -> dict:
        """Facts about the configured variant: trainable parameters, disparity grid, weights."""
        from lfbench_methods.subfocal.keras_import import load_checkpoint
        from lfbench_methods.subfocal.network import SubFocalNet, count_trainable

        path = self.weights_path
        config = self._configured()
        if path is None:
            weights = "none (predictions need weights=CHECKPOINT.pt)"
        elif not path.is_file():
            weights = f"{path} (missing)"
        else:
            _, stored, source = load_checkpoint(path)
            config = self.check_config(stored)
            kind = "given" if self.weights is not None else "shipped"
            weights = f"{path} ({kind}{'; source ' + source if source else ''})"
        net = SubFocalNet(**config)
        d = net.disparities
        return {"trainable_parameters": count_trainable(net), "disparities": d.numel(),
                "disparity_grid": f"[{config['d_min']:g}, {config['d_max']:g}] step {config['interval']:g}",
                "interpolation": config["interpolation"], "width": config["width"],
                "attention": config["attention"], "weights": weights}

    # -- prediction -------------------------------------------------------------------------

    def available_for(self, lf: LightField) -> str | None:
        reason = self.missing_reason()
        if reason:
            return reason
        angular = self.load_network().angular  # the weights' grid of views (9x9 for HCI; a 7x7 net takes 7x7)
        v, u = lf.angular_size
        if (v, u) != (angular, angular):
            return f"needs a {angular}x{angular} light field, got {v}x{u} views"
        return None

    def predict(self, lf: LightField) -> Prediction:
        import numpy as np
        import torch
        from lfbench_methods.subfocal.inference import infer

        from lfbench.utils.hardware import set_fp32_numerics
        from lfbench.utils.threads import torch_threads

        net = self.load_network()
        v, u = lf.angular_size
        if (v, u) != (net.angular, net.angular):
            raise DataError(f"{self.label}: needs a {net.angular}x{net.angular} light field, got {v}x{u} views "
                            f"({lf.name})")
        views = lf.gray_views()
        x = torch.from_numpy(np.ascontiguousarray(views.reshape(v * u, *views.shape[2:]), dtype=np.float32))
        if self.device.type == "cuda":
            set_fp32_numerics(tf32=self.values["tf32"])  # IEEE fp32 unless tf32=true
        budget = self.values["max_memory_gb"] if "max_memory_gb" in self.params else None  # None: the device's
        with torch_threads(self.values["threads"]):
            out = infer(net, x, tile=self.values["tile"], max_memory_gb=budget, precision=self.values["precision"])
        return Prediction(disparity=out.disparity[0].numpy(), distribution=out.probability[0].numpy(),
                          disparity_values=out.disparities.numpy(), uncertainty=out.uncertainty[0].numpy())


def _signature_defaults() -> dict:
    return {k: p.default for k, p in inspect.signature(SubFocal.__init__).parameters.items() if k != "self"}


def _architecture(values: dict) -> dict:
    """The architecture of a set of SubFocal parameters (width: the paper's 150 unless given)."""
    v = values
    return {"d_min": float(v["d_min"]), "d_max": float(v["d_max"]), "interval": float(v["interval"]),
            "interpolation": v["interpolation"], "width": int(v["width"] or PAPER_WIDTH),
            "attention": bool(v["attention"]), "angular": 9}


def _stored_config(path: Path) -> dict:
    from lfbench_methods.subfocal.keras_import import load_checkpoint

    return load_checkpoint(path)[1]


__all__ = ["SubFocal", "SubFocalTrainable", "LFAttNetTrainable", "WEIGHTS_DIR", "PAPER_WIDTH"]
