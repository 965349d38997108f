"""The generic network method: runs the weights of any registered trainable network, so that a plugin
registers its network once (``@register_trainable``) and ``lfbench evaluate --method NAME:weights=PATH``
works.

Its parameters (``lfbench info NAME``) are the runtime ones, :data:`RUNTIME_PARAMS` (``weights``,
``device``, ``precision``, ``threads``, ``tile``: exact tiles, for a network that has a receptive radius),
and the network's constructor parameters. The weights file's stored config decides the architecture;
a network parameter given in the spec must agree with it (a conflict is one error line), so a spec
names what it expects to run. Without weights the method does not run (never random weights):
``available_for`` says so and evaluations skip it.

Inference goes through :meth:`Trainable.infer` (whole image, or exact tiles), on the device given
(``auto``: the GPU when torch sees one), in fp32 (IEEE: no TF32) or bf16 autocast. The prediction
carries the network's distribution over its disparities when it has one, and its standard deviation
as the uncertainty map (px).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar, Literal

import numpy as np

from lfbench.data.scene import LightField
from lfbench.method.base import Method, Prediction
from lfbench.method.checkpoint import check_checkpoint_file
from lfbench.method.params import Param, Range
from lfbench.method.trainable import Trainable, contract_problem, get_trainable, plugin_failure
from lfbench.utils.errors import DataError, LFBenchError, SpecError
from lfbench.utils.flags import THREADS
from lfbench.utils.hardware import DEVICE_HELP

if TYPE_CHECKING:
    import torch

PRECISIONS = ("fp32", "bf16")

#: The parameters every network method has besides its network's.
RUNTIME_PARAMS: dict[str, Param] = {
    "weights": Param("weights", Path | None, None,
                     "weights file of this network (lfbench train writes OUT/final.pt); required to run"),
    "device": Param("device", str, "auto", DEVICE_HELP),
    "precision": Param("precision", Literal["fp32", "bf16"], "fp32",
                       "fp32 (IEEE), or bf16 autocast of the forward pass (needs bf16 convolutions)"),
    "threads": THREADS,  # the same declaration as lfbench bench --threads
    "tile": Param("tile", int, 0, "inference tile size in px (0 = the whole image; exact: each tile is run with "
                                  "the network's receptive radius of context; networks that have one)",
                  Range(0, 1 << 16)),
}


def network_method_params(trainable: Trainable) -> dict[str, Param]:
    """The parameters of the network method of ``trainable``: :data:`RUNTIME_PARAMS`, then the network's own
    (default: the weights file's)."""
    network = {k: p for k, p in trainable.parameters().items() if k not in RUNTIME_PARAMS}
    return {**RUNTIME_PARAMS, **network}


def distribution_std(probability: torch.Tensor, disparities: torch.Tensor, mean: torch.Tensor) -> torch.Tensor:
    """(B, D, H, W), (D,), (B, H, W) -> (B, H, W): sqrt(sum_k p_k (d_k - mean)^2) in px."""
    dev = disparities[None, :, None, None] - mean[:, None]
    return (probability * dev * dev).sum(dim=1).clamp_min(0).sqrt()


class NetworkMethod(Method):
    """Runs the weights of a registered trainable network (``NAME:weights=PATH[,key=value,...]``).

    ``network``: the trainable's name (a subclass may fix it as a class attribute); ``weights``: the
    weights file; ``arch``: network parameters the weights must have (checked when they are loaded: the
    registry records them in ``params``, :meth:`explicit_arch`).
    """

    network: ClassVar[str] = ""
    content_params = ("weights",)

    def __init__(self, *, network: str | None = None, weights: Path | None = None, device: str = "auto",
                 precision: str = "fp32", threads: int = 0, tile: int = 0, **arch: Any) -> None:
        from lfbench.utils.hardware import require_bf16, resolve_device

        given = {"weights": weights, "device": device, "precision": precision, "threads": threads, "tile": tile}
        defaults = {k: p.default for k, p in RUNTIME_PARAMS.items()}
        super().__init__(**{k: v for k, v in given.items() if v != defaults[k]}, **arch)
        self.trainable = get_trainable(network or self.network)
        if precision not in PRECISIONS:
            raise ValueError(f"precision must be {' or '.join(PRECISIONS)}, got {precision!r}")
        if threads < 0 or tile < 0:
            raise ValueError("threads and tile must be >= 0")
        self.trainable.check_values(arch)  # types and bounds of the network parameters given
        self.weights = None if weights is None else Path(weights).expanduser()
        self.device = resolve_device(device)  # SpecError for a device this machine lacks
        if precision == "bf16":
            require_bf16(self.device)  # one line, before any work
        self.precision, self.threads, self.tile = precision, threads, tile
        self._net: torch.nn.Module | None = None

    # -- weights ---------------------------------------------------------------------------------

    @property
    def weights_path(self) -> Path | None:
        """The weights file to load (None: none given)."""
        return self.weights

    def check_content(self, key: str, path: Path) -> None:
        """The weights file must look like a torch checkpoint (kind and size from bounded reads:
        :func:`lfbench.method.checkpoint.check_checkpoint_file`) before its hash names the method."""
        if key == "weights":
            check_checkpoint_file(path, "weights file")

    def explicit_arch(self) -> dict[str, Any]:
        """The network parameters the user gave (recorded by the registry in ``params``)."""
        names = set(self.trainable.parameters())
        return {k: v for k, v in self.params.items() if k in names}

    def missing_reason(self) -> str | None:
        """Why there is no weights file to load (None when there is one)."""
        path = self.weights_path
        if path is None:
            return (f"no weights: give {self.name or self.trainable.name}:weights=FILE.pt (lfbench train writes "
                    "OUT/final.pt); a network method never runs with random weights")
        if path.is_file():
            return None
        return f"weights file {path} is not a regular file" if path.exists() else f"weights file {path} not found"

    @classmethod
    def range_from_weights(cls, info: Any, params: dict[str, Any]) -> bool:
        """Whether the weights fix the disparity grid (lfbench.data.dataset.method_range_params): always, for a
        network run from a weights file (its stored config decides every network parameter, d_min / d_max of a
        network that has them included, and a given one that contradicts it is an error; without weights it
        does not run). SubFocal, with shipped weights of one architecture only, narrows this."""
        return True

    def conflicts(self, stored: dict[str, Any]) -> list[str]:
        """The given network parameters that the stored config contradicts, as ``key=given (checkpoint: stored)``."""
        out = []
        for key, value in self.explicit_arch().items():
            theirs = stored.get(key)
            numbers = all(isinstance(v, int | float) and not isinstance(v, bool) for v in (value, theirs))
            same = abs(float(theirs) - float(value)) < 1e-9 if numbers else theirs == value
            if not same:
                out.append(f"{key}={value} (checkpoint: {theirs})")
        return out

    def check_config(self, stored: dict[str, Any]) -> dict[str, Any]:
        """``stored`` after checking the given network parameters against it (SpecError on a conflict)."""
        wrong = self.conflicts(stored)
        if wrong:
            raise SpecError(f"{self.name or self.trainable.name}: {', '.join(wrong)} conflicts with the weights "
                            f"{self.weights_path}; leave it out to use the weights' own")
        return stored

    def load_network(self) -> torch.nn.Module:
        """The network with the weights (eval mode, on this method's device), loaded once."""
        if self._net is None:
            reason = self.missing_reason()
            if reason:
                raise DataError(reason)
            # the architecture the weights were trained with (a key left out: the network's default), checked
            # against the parameters given before anything is built; DataError for a file of another kind
            defaults = {k: p.default for k, p in self.trainable.parameters().items() if not p.required}
            self.check_config({**defaults, **self.trainable.stored_config(self.weights_path)})
            net = self.trainable.load(self.weights_path)
            if self.tile and not self.trainable.can_tile(net):
                raise SpecError(f"{self.name or self.trainable.name}: tile={self.tile}, but network "
                                f"{self.trainable.name!r} runs on whole images only (it has no receptive_radius)")
            self._net = net.to(self.device)
        return self._net

    def to(self, device: str) -> NetworkMethod:
        """Load the network (once) and move it to ``device`` (where predict then runs)."""
        from lfbench.utils.hardware import resolve_device

        self.device = resolve_device(device)
        self.load_network().to(self.device)
        return self

    # -- running ---------------------------------------------------------------------------------

    def available_for(self, lf: LightField) -> str | None:
        """A reason without weights; with them, the network is loaded here (once), so that foreign or
        conflicting weights are one error before any scene runs."""
        reason = self.missing_reason()
        if reason:
            return reason
        net = self.load_network()
        angular = int(getattr(net, "angular", 9))
        if tuple(lf.angular_size) != (angular, angular):
            v, u = lf.angular_size
            return f"needs a {angular}x{angular} light field, got {v}x{u} views"
        return None

    def predict(self, lf: LightField) -> Prediction:
        import torch

        from lfbench.utils.hardware import set_fp32_numerics
        from lfbench.utils.threads import torch_threads

        net = self.load_network()
        angular = int(getattr(net, "angular", 9))
        v, u = lf.angular_size
        if (v, u) != (angular, angular):
            raise DataError(f"{self.label}: needs a {angular}x{angular} light field, got {v}x{u} views ({lf.name})")
        views = self.trainable.views_of(lf)  # (V, U, H, W) float32 in [0, 1]
        x = torch.from_numpy(np.ascontiguousarray(views.reshape(1, v * u, *views.shape[2:]), dtype=np.float32))
        if self.device.type == "cuda":
            set_fp32_numerics(tf32=False)  # fp32 is IEEE fp32
        h, w = views.shape[2:]
        source = f"{self.label} on {lf.name}"
        try:
            with torch_threads(self.threads if self.device.type == "cpu" else None):
                out = self.trainable.infer(net, x.to(self.device), precision=self.precision, tile=self.tile)
        except LFBenchError:
            raise
        except Exception as exc:  # noqa: BLE001 - whatever the plugin's forward raised: one line
            raise DataError(f"{source}: {plugin_failure(f'network {self.trainable.name!r} ({w}x{h} px)', exc)}"
                            ) from None
        values = getattr(net, "disparities", None)
        problem = contract_problem(out, (h, w), values)  # the one check of a prediction, on the tensors
        if problem:
            raise DataError(f"{source}: network {self.trainable.name!r} breaks the network contract: {problem}")
        disparity, probability = out
        disparity = disparity.float()[0].cpu()
        if probability is None or values is None:
            return Prediction(disparity=disparity.numpy())
        probability = probability.float()[0].cpu()
        values = values.float().cpu()
        std = distribution_std(probability[None], values, disparity[None])[0]
        return Prediction(disparity=disparity.numpy(), distribution=probability.numpy(),
                          disparity_values=values.numpy(), uncertainty=std.numpy())

    def describe_variant(self) -> dict[str, Any]:
        """The network and its weights: file, SHA-256, the architecture stored in it, trainable parameters."""
        facts: dict[str, Any] = {"network": self.trainable.name}
        path = self.weights_path
        if path is None or not path.is_file():
            facts["weights"] = self.missing_reason()
            return facts
        net = self.load_network()
        facts["weights"] = str(path)
        facts["weights_sha256"] = self.provenance()["weights"]["sha256"]
        facts["architecture"] = ", ".join(f"{k}={v}" for k, v in self.trainable.stored_config(path).items())
        facts["trainable_parameters"] = sum(p.numel() for p in net.parameters() if p.requires_grad)
        return facts


__all__ = ["NetworkMethod", "RUNTIME_PARAMS", "network_method_params", "distribution_std", "PRECISIONS"]
