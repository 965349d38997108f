"""``lfbench check-plugin NAME``: a registered network run against every part of the plugin contract on tiny
generated light fields, each finding one line saying what to fix.

The checks (:func:`check_plugin`, in order; a check whose prerequisite failed is skipped):

- ``build``: the network builds from its parameters (defaults, or those of the spec) and is a ``torch.nn.Module``;
- ``forward``: on a batch of 2 light fields of H x W (not square) random views, ``forward`` returns
  ``(disparity (2, H, W) float32, finite; probability (2, D, H, W) float32, >= 0, summing to 1 over D, or None)``,
  ``disparities`` a (D,) ascending, evenly spaced tensor when there is a probability, and a probability when the
  trainable says ``distribution = True``;
- ``sign``: with trained weights only (``--weights``; a network with random weights has no sign), the
  prediction on two generated planes at +D and -D px (:func:`lfbench.data.synth.plane_views`) must follow the
  disparity with lfbench's sign (a point of the centre view at (x, y) appears in view (u, v) at
  (x - (u - c) d, y - (v - c) d));
- ``receptive_radius``: when declared, an int >= 0, and a change of one input pixel changes no output farther
  away than it;
- ``tiling``: when the network can tile, exact tiles equal the whole image;
- ``flops``: when declared, a number or ``{"total": n, ...}``, growing with the image, and not below what
  torch's FLOP counter measures of its convolutions and matrix products;
- ``save/load``: weights written as ``lfbench train`` writes them load back (``config()`` rebuilds the
  network) and give the same output;
- ``training``: one optimizer step (the trainable's ``configure_optimizers``, lfbench's L1 loss, and a
  distribution loss when it has a distribution) is finite and changes every parameter.

A network that declares an output margin (valid convolutions: :meth:`Trainable.output_margin`) is checked on
light fields of at least 2 x margin + 4 px, and its training step's loss compares the inner part, as
``lfbench train`` does.
"""

from __future__ import annotations

import math
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace
from typing import TYPE_CHECKING, Any

from lfbench.method.trainable import Trainable, crop_margin, get_trainable, plugin_source
from lfbench.utils.errors import LFBenchError, PluginError, SpecError
from lfbench.utils.watchdog import TimeLimitExceeded, time_limit

if TYPE_CHECKING:
    import torch

OK, FAIL, SKIP = "ok", "FAIL", "skip"
SIGN_DISPARITY = 1.0  # px per view step of the sign check's two planes (less for a network of a narrower range)
SIGN_SIZE = 32  # px of those planes
TILE = 8  # px of the tiles of the tiling check
TOLERANCE = 1e-4  # px (and probability) a tiled or reloaded output may differ by (float rounding)


@dataclass(frozen=True)
class Finding:
    """One check: its name, OK / FAIL / SKIP and one line (what was found; for a failure, what to fix)."""

    check: str
    status: str
    text: str

    def line(self) -> str:
        return f"{self.status:<4}  {self.check}: {self.text}"


class _Failed(Exception):
    """A check's failure line (raised inside a check)."""


def check_plugin(name: str, params: dict[str, Any] | None = None, *, weights: str | Path | None = None,
                 size: int = 20, seed: int = 0, timeout: float | None = None) -> list[Finding]:
    """Every check of the module docstring on network ``name`` built with ``params`` (its network parameters)
    and, with ``weights``, the trained weights of that file (read as the network method reads them).
    SpecError/DataError (exit 2) for an unknown name, bad parameters or an unreadable weights file; LFBenchError
    (exit 2) when a check, or the parameters' check that builds the network, runs past ``timeout`` seconds (None:
    no bound; lfbench.utils.watchdog)."""
    import torch

    trainable = get_trainable(name)
    params = dict(params or {})

    def too_long(what: str) -> LFBenchError:
        return LFBenchError(f"network {name!r} ({plugin_source(trainable)}): {what} did not finish within "
                            f"{timeout:g} s (--timeout): its constructor or forward runs too long")

    try:
        with time_limit(timeout):
            trainable.check_values(params)
            if params:
                trainable.check_params(params)
    except TimeLimitExceeded:
        raise too_long("building it from its parameters") from None
    except (TypeError, ValueError) as exc:
        with time_limit(timeout):
            builds = not params or _builds(trainable, {})
        if builds:  # the values given are bad (the defaults build): bad input
            raise SpecError(f"network {name!r}: {exc}") from None
    ctx = _Context(trainable, params, size, seed)
    findings: list[Finding] = []

    def run(check: str, fn: Callable[[], tuple[str, str]], *needs: str) -> None:
        missing = [n for n in needs if not any(f.check == n and f.status == OK for f in findings)]
        if missing:
            findings.append(Finding(check, SKIP, f"needs a passing {' and '.join(missing)} check"))
            return
        try:
            with time_limit(timeout):
                status, text = fn()
        except TimeLimitExceeded:
            raise too_long(f"the {check} check") from None
        except _Failed as exc:
            status, text = FAIL, str(exc)
        except LFBenchError:
            raise
        except Exception as exc:  # noqa: BLE001 - whatever the plugin raised: one line naming it
            status, text = FAIL, f"raised {_one_line(exc)}"
        except SystemExit as exc:  # sys.exit in a plugin's code would end the check with exit 0 and no word
            status, text = FAIL, f"raised SystemExit({exc.code!r}): a network must never exit the process"
        findings.append(Finding(check, status, text))

    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        run("build", ctx.build)
        run("forward", ctx.forward, "build")
        if weights is None:
            findings.append(Finding("sign", SKIP, "no --weights: a network with random weights has no sign; train it "
                                                  f"(lfbench train CONFIG --out RUN) and run check-plugin {name} "
                                                  "--weights RUN/final.pt"))
        else:
            try:
                with time_limit(timeout):
                    trained = trainable.load(weights)  # DataError naming the file: bad input
            except TimeLimitExceeded:
                raise too_long("loading --weights") from None
            run("sign", lambda: ctx.sign(trained), "forward")
        run("receptive_radius", ctx.receptive_radius, "forward")
        run("tiling", ctx.tiling, "forward")
        run("flops", ctx.flops, "forward")
        run("save/load", ctx.save_load, "forward")
        run("training", ctx.training, "forward")
    return findings


def _builds(trainable: Trainable, params: dict[str, Any]) -> bool:
    """Whether the network builds from ``params`` (on the meta device where it can)."""
    try:
        trainable.check(params)
    except (Exception, SystemExit):  # noqa: BLE001 - whatever the constructor raised
        return False
    return True


def _one_line(exc: BaseException) -> str:
    first = (str(exc).strip().splitlines() or [""])[0][:200]
    return f"{type(exc).__name__}: {first}" if first else type(exc).__name__


class _Context:
    """The network under check and what the checks share."""

    def __init__(self, trainable: Trainable, params: dict[str, Any], size: int, seed: int) -> None:
        self.trainable, self.params, self.size, self.seed = trainable, params, size, seed
        self.net: torch.nn.Module | None = None

    # -- helpers ---------------------------------------------------------------------------------

    @property
    def angular(self) -> int:
        return int(getattr(self.net, "angular", 9))

    def views(self, batch: int, height: int, width: int, seed: int = 0) -> torch.Tensor:
        import torch

        g = torch.Generator().manual_seed(self.seed + seed)
        return torch.rand((batch, self.angular ** 2, height, width), generator=g)

    def fresh(self) -> torch.nn.Module:
        """Another network of the same parameters (its own random initialisation)."""
        return self.trainable.build(**self.params)

    def infer(self, net: torch.nn.Module, views: torch.Tensor, **options: Any) -> tuple[torch.Tensor, Any]:
        return self.trainable.infer(net, views, precision="fp32", **options)

    # -- checks: each returns (status, line) or raises _Failed(line) -----------------------------

    def build(self) -> tuple[str, str]:
        import torch

        try:
            net = self.fresh()
        except (Exception, SystemExit) as exc:  # noqa: BLE001 - the constructor's own error
            raise _Failed(f"{self.trainable.name}({_kwargs(self.params)}) raised {_one_line(exc)}: the network must "
                          "build from its parameters' defaults") from None
        if not isinstance(net, torch.nn.Module):
            raise _Failed(f"build() returned a {type(net).__name__}, not a torch.nn.Module")
        angular = getattr(net, "angular", 9)
        if not isinstance(angular, int) or isinstance(angular, bool) or not 1 <= angular <= 15:
            raise _Failed(f"angular is {angular!r}: declare the views per angular row as an int (9 for HCI)")
        self.net = net.eval()
        # a network of valid convolutions needs more than its output margin on each side: the checks' light
        # fields grow to fit it (e.g. EPINET's 11 px: at least 23 px)
        self.size = max(self.size, 2 * self.trainable.output_margin(net) + 4)
        count = sum(p.numel() for p in net.parameters())
        if not count:
            raise _Failed("the network has no parameters: lfbench trains and loads parameters (nn.Parameter, "
                          "layers in nn.Module attributes)")
        return OK, f"{type(net).__name__}({_kwargs(self.params)}): {count:,} parameters, {angular}x{angular} views"

    def forward(self) -> tuple[str, str]:
        import torch

        h, w = self.size, self.size + 4  # not square: height and width must not be swapped
        out = self.infer(self.net, self.views(2, h, w))
        if not isinstance(out, tuple | list) or len(out) != 2:
            raise _Failed(f"forward returned a {type(out).__name__}: return (disparity (B, H, W), probability "
                          "(B, D, H, W) or None)")
        disparity, probability = out
        if not isinstance(disparity, torch.Tensor) or tuple(disparity.shape) != (2, h, w):
            got = tuple(disparity.shape) if isinstance(disparity, torch.Tensor) else type(disparity).__name__
            raise _Failed(f"disparity is {got} for views (2, {self.angular ** 2}, {h}, {w}): return (B, H, W) = "
                          f"(2, {h}, {w})")
        if disparity.dtype != torch.float32:
            raise _Failed(f"disparity is {disparity.dtype} in fp32: return float32")
        if not torch.isfinite(disparity).all():
            raise _Failed("disparity holds NaN or inf on random views in [0, 1]")
        text = f"disparity (2, {h}, {w}) float32"
        values = getattr(self.net, "disparities", None)
        if probability is None:
            if self.trainable.distribution:
                raise _Failed("distribution = True but forward returns no probability: return (disparity, "
                              "probability (B, D, H, W)) or set distribution = False")
            return OK, text + ", no probability"
        if not isinstance(values, torch.Tensor) or values.dim() != 1 or values.numel() < 2:
            raise _Failed("forward returns a probability but net.disparities is not a (D,) tensor of its candidate "
                          "disparities (register_buffer('disparities', torch.linspace(d_min, d_max, D)))")
        d = values.numel()
        if not isinstance(probability, torch.Tensor) or tuple(probability.shape) != (2, d, h, w):
            got = tuple(probability.shape) if isinstance(probability, torch.Tensor) else type(probability).__name__
            raise _Failed(f"probability is {got}: return (B, D, H, W) = (2, {d}, {h}, {w}) over net.disparities")
        if probability.dtype != torch.float32:
            raise _Failed(f"probability is {probability.dtype} in fp32: return float32 (softmax(...).float())")
        sums = probability.sum(dim=1)
        if not torch.isfinite(probability).all() or (probability < 0).any() or (sums - 1).abs().max() > 1e-3:
            raise _Failed("probability is not a distribution over D (>= 0, summing to 1): return "
                          "torch.softmax(logits, dim=1)")
        steps = values.double().diff()
        if (steps <= 0).any() or (steps - steps.mean()).abs().max() > 1e-4 * max(1.0, float(steps.abs().max())):
            raise _Failed("net.disparities must ascend in even steps (torch.linspace(d_min, d_max, D))")
        note = "" if self.trainable.distribution else " (distribution = False: the distribution losses stay off)"
        return OK, (f"{text}, probability (2, {d}, {h}, {w}) float32 over {d} disparities "
                    f"{float(values[0]):g} to {float(values[-1]):g} px{note}")

    def sign(self, trained: torch.nn.Module) -> tuple[str, str]:
        import torch

        from lfbench.data.synth import plane_views

        values = getattr(trained, "disparities", None)
        reach = float(values.abs().max()) if isinstance(values, torch.Tensor) and values.numel() else SIGN_DISPARITY
        d = min(SIGN_DISPARITY, 0.5 * reach)
        angular = int(getattr(trained, "angular", 9))
        border = max(4, SIGN_SIZE // 8)
        means = []
        for value in (d, -d):
            views = torch.from_numpy(plane_views(value, SIGN_SIZE, angular, seed=self.seed)).reshape(
                1, angular * angular, SIGN_SIZE, SIGN_SIZE)
            disparity, _ = self.infer(trained.eval(), views)
            means.append(float(disparity[0, border:-border, border:-border].float().mean()))
        plus, minus = means
        found = f"on planes at +{d:g} and -{d:g} px it predicts {plus:+.3f} and {minus:+.3f} px"
        if plus - minus >= 0.2 * 2 * d:
            return OK, found
        if minus - plus >= 0.2 * 2 * d:
            raise _Failed(f"{found}: the opposite sign. lfbench's disparity d is positive when a point of the "
                          "centre view at (x, y) appears in view (u, v) at (x - (u - c) d, y - (v - c) d) (as in the "
                          "HCI data): flip the direction of your shifts (or of net.disparities)")
        raise _Failed(f"{found}: it does not follow the disparity. Train longer, or check the view order (view k at "
                      "row k // angular, column k % angular)")

    def receptive_radius(self) -> tuple[str, str]:
        import torch

        declared = getattr(self.net, "receptive_radius", None)
        own = type(self.trainable).receptive_radius is not Trainable.receptive_radius
        if not own and declared is not None and (not isinstance(declared, int) or isinstance(declared, bool)
                                                 or declared < 0):
            raise _Failed(f"receptive_radius is {declared!r} ({type(declared).__name__}): declare an int >= 0, the "
                          "px of context one output pixel depends on (or leave it out: whole images only)")
        radius = self.trainable.receptive_radius(self.net)
        if radius is None and self.trainable.can_tile(self.net):
            return SKIP, "not declared: the trainable's own infer() runs the tiles (the tiling check compares them)"
        if radius is None:
            return SKIP, ("not declared: the network runs on whole images only (tile= refused); declare "
                          "receptive_radius (px of context per output pixel) to run in exact tiles")
        side = min(128, max(self.size + 4, 2 * radius + 9))
        views = self.views(1, side, side, seed=1)
        y = x = side // 2
        changed = views.clone()
        changed[..., y, x] = 1.0 - changed[..., y, x]
        a, b = self.infer(self.net, views), self.infer(self.net, changed)
        moved = (a[0] - b[0]).abs()[0] > TOLERANCE * (1 + a[0].abs()[0])
        if a[1] is not None and b[1] is not None:
            moved |= ((a[1] - b[1]).abs() > TOLERANCE).any(dim=1)[0]
        ys, xs = torch.nonzero(moved, as_tuple=True)
        reach = int(torch.maximum((ys - y).abs(), (xs - x).abs()).max()) if ys.numel() else 0
        if reach > radius:
            hint = " (the whole image: global context has no finite radius; leave receptive_radius out)" \
                if reach >= side // 2 - 1 else ""
            raise _Failed(f"declared {radius} px, but a change of one pixel moved outputs {reach} px away{hint}: "
                          f"declare receptive_radius >= {reach}")
        return OK, f"{radius} px (a change of one pixel moved outputs up to {reach} px away on {side}x{side} px)"

    def tiling(self) -> tuple[str, str]:
        if not self.trainable.can_tile(self.net):
            return SKIP, "the network runs on whole images only (no receptive_radius)"
        radius = self.trainable.receptive_radius(self.net) or 0
        h = min(128, max(3 * TILE, 2 * radius + TILE + 4))
        w = h + 4
        views = self.views(1, h, w, seed=2)
        diff = _agree(self.infer(self.net, views), self.infer(self.net, views, tile=TILE), lambda d: (
            f"tiles of {TILE} px differ from the whole image by {d:.3g} on {h}x{w} px: the output depends on more "
            f"than receptive_radius = {radius} px of context (declare the true radius) or on where the image ends"))
        return OK, f"tiles of {TILE} px equal the whole image on {h}x{w} px (max difference {diff:.2g})"

    def flops(self) -> tuple[str, str]:
        import torch
        from torch.utils.flop_counter import FlopCounterMode

        h, w = self.size, self.size + 4
        try:
            small = self.trainable.flop_count(self.net, h, w)
            large = self.trainable.flop_count(self.net, 2 * h, 2 * w)
        except PluginError as exc:
            raise _Failed(str(exc)) from None
        if small is None:
            return SKIP, ("flops() not declared: bench records carry no GFLOP/s; return the FLOPs of one forward "
                          "pass on an H x W light field (a number, or {'total': n, ...})")
        if not large["total"] > small["total"] > 0:
            raise _Failed(f"flops() gives {small['total']:.4g} at {h}x{w} and {large['total']:.4g} at {2 * h}x{2 * w}: "
                          "count one forward pass on an H x W light field (it grows with height * width)")
        counter = FlopCounterMode(display=False)
        with torch.no_grad(), counter:
            self.net(self.views(1, h, w))
        measured = float(counter.get_total_flops())
        if measured and small["total"] < 0.9 * measured:
            raise _Failed(f"flops() says {small['total']:.4g} at {h}x{w}, torch's FLOP counter measures "
                          f"{measured:.4g} in convolutions and matrix products alone: count FLOPs (2 per "
                          "multiply-add, not GFLOPs or MACs) of the whole image")
        parts = ", ".join(f"{k} {v:.3g}" for k, v in small.items() if k != "total")
        return OK, (f"{small['total']:.4g} FLOPs at {h}x{w}{' (' + parts + ')' if parts else ''}; torch's counter "
                    f"measures {measured:.4g} in convolutions and matrix products")

    def save_load(self) -> tuple[str, str]:

        from lfbench.training.checkpoint import export_weights

        with tempfile.TemporaryDirectory(prefix="lfbench-check-") as tmp:
            path = Path(tmp) / "final.pt"
            config = self.trainable.config_of(self.net, self.params)
            export_weights(path, self.net, {}, method=self.trainable.name, config=config)
            try:
                loaded = self.trainable.load(path)
            except LFBenchError as exc:
                text = str(exc).replace(str(path), "the saved weights")
                raise _Failed(f"{text}: config() must return the plain keyword arguments (numbers, strings, lists) "
                              "that rebuild the network") from None
        views = self.views(1, self.size, self.size, seed=3)
        _agree(self.infer(self.net, views), self.infer(loaded, views), lambda d: (
            f"the reloaded network's output differs by {d:.3g}: config() ({_kwargs(config)}) must hold every "
            "argument that changes the network, and every tensor that matters must be a parameter or a persistent "
            "buffer"))
        return OK, f"weights written as lfbench train writes them load back with config {_kwargs(config) or '{}'}"

    def training(self) -> tuple[str, str]:
        import torch

        from lfbench.training.losses import make_loss

        net = self.fresh().train()
        stage = SimpleNamespace(name="check", lr=1e-3, steps=1, eps=1e-7, betas=(0.9, 0.999))
        made = self.trainable.configure_optimizers(net, stage)
        optimizer = made[0] if isinstance(made, tuple) else made
        before = {k: p.detach().clone() for k, p in net.named_parameters()}
        g = torch.Generator().manual_seed(self.seed + 4)
        margin = self.trainable.output_margin(net)
        side = 16 + 2 * margin  # the loss compares 16 x 16 px, as for a network without a margin
        views = torch.rand((2, self.angular ** 2, side, side), generator=g)
        values = getattr(net, "disparities", None)
        lo, hi = (float(values.min()), float(values.max())) if isinstance(values, torch.Tensor) else (-2.0, 2.0)
        target = lo + (hi - lo) * (0.1 + 0.8 * torch.rand((2, side, side), generator=g))
        loss_name = "l1+js" if self.trainable.distribution else "l1"
        optimizer.zero_grad(set_to_none=True)
        disparity, probability, target = crop_margin(*self.trainable.training_forward(net, views, target), target,
                                                     margin)  # as lfbench train compares
        loss = make_loss(loss_name)(disparity, probability, target, values)
        value = float(loss.detach())
        if not math.isfinite(value):
            raise _Failed(f"the {loss_name} loss of one step is {value}")
        loss.backward()
        no_grad = [k for k, p in net.named_parameters() if p.requires_grad and p.grad is None]
        bad = [k for k, p in net.named_parameters() if p.grad is not None and not torch.isfinite(p.grad).all()]
        optimizer.step()
        same = [k for k, p in net.named_parameters() if torch.equal(p.detach(), before[k])]
        if bad:
            raise _Failed(f"gradients of {', '.join(bad[:3])} hold NaN or inf after one {loss_name} step")
        if no_grad:
            raise _Failed(f"{len(no_grad)} parameter(s) get no gradient from the {loss_name} loss "
                          f"({', '.join(no_grad[:3])}): they are never trained; use them in forward or remove them")
        if same:
            raise _Failed(f"one optimizer step left {len(same)} of {len(before)} parameters unchanged "
                          f"({', '.join(same[:3])}): configure_optimizers must optimise net.parameters()")
        return OK, f"one {loss_name} step (loss {value:.4g}) changed all {len(before)} parameter tensors"


def _agree(a: tuple, b: tuple, failure: Callable[[float], str]) -> float:
    """The largest |a - b| of two forward results' disparities and, when both have one, probabilities;
    ``_Failed(failure(difference))`` when it exceeds TOLERANCE."""
    diff = float((a[0] - b[0]).abs().max())
    if a[1] is not None and b[1] is not None:
        diff = max(diff, float((a[1] - b[1]).abs().max()))
    if not diff <= TOLERANCE:
        raise _Failed(failure(diff))
    return diff


def _kwargs(params: dict[str, Any]) -> str:
    return ", ".join(f"{k}={v!r}" for k, v in params.items())


def summary(name: str, findings: list[Finding]) -> str:
    """The last line: how many checks passed, failed and were skipped."""
    counts = {s: sum(f.status == s for f in findings) for s in (OK, FAIL, SKIP)}
    verdict = "FAILED" if counts[FAIL] else "passed"
    return (f"{name} ({plugin_source(get_trainable(name))}): {verdict}: {counts[OK]} ok, {counts[FAIL]} failed, "
            f"{counts[SKIP]} skipped")


def failed(findings: list[Finding]) -> bool:
    return any(f.status == FAIL for f in findings)


__all__ = ["Finding", "check_plugin", "summary", "failed", "OK", "FAIL", "SKIP", "TILE", "SIGN_DISPARITY"]
