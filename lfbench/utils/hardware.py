"""What this machine can run, and where tensors live: bf16 convolutions on the CPU, CUDA devices, and the
fp32 numerics policy.

- :func:`cpu_bf16_missing` says whether this CPU runs bfloat16 convolutions natively (oneDNN's bf16 path
  needs AVX-512 BW+VL+DQ, AVX-NE-CONVERT or AMX; on an AVX2-only CPU ``mkldnn_convolution`` raises, and
  ``F.conv2d`` on small shapes silently falls back to a slow emulation). It asks oneDNN itself (torch's
  ``_is_mkldnn_bf16_supported``) and runs a tiny bf16 conv2d and conv3d through ``mkldnn_convolution``, the
  kernel path real shapes and the fused ops take, once, and caches the answer. ``LFBENCH_FORCE_NO_BF16=1``
  makes it answer as on an AVX2-only CPU (tests of that behaviour on machines that have the instructions).
- :func:`require_bf16` turns a missing capability into one :class:`SpecError` line naming it and the
  alternative, before any work.
- :func:`resolve_device` maps ``auto`` / ``cpu`` / ``cuda`` / ``cuda:K`` to a ``torch.device`` (SpecError
  for a device this machine does not have).
- :func:`set_fp32_numerics`: fp32 means IEEE fp32 (no TF32 in matmuls or cuDNN convolutions) unless
  ``tf32=True`` opts in; :func:`fp32_numerics` reports what is on.
"""

from __future__ import annotations

import functools
import os
import re
from pathlib import Path

from lfbench.utils.errors import SpecError

FORCE_NO_BF16_ENV = "LFBENCH_FORCE_NO_BF16"
# oneDNN's bf16 convolution path: these three AVX-512 subsets together, or avx_ne_convert, or AMX.
BF16_AVX512_FLAGS = ("avx512bw", "avx512vl", "avx512dq")
DEVICE_HELP = "auto (CUDA when available, else CPU), cpu, cuda or cuda:K"
_DEVICE_RE = re.compile(r"^(auto|cpu|cuda)(?::(\d+))?$")


CPUINFO = Path("/proc/cpuinfo")


def available_cores() -> int:
    """The CPU cores this process may run on (its affinity mask on Linux, else os.cpu_count())."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def cpuinfo_field(name: str, cpuinfo: Path = CPUINFO) -> str | None:
    """The value of the first ``name : value`` line of /proc/cpuinfo (``name`` matched without case),
    stripped; None where the file or the line does not exist."""
    try:
        text = cpuinfo.read_text(encoding="utf-8", errors="replace")
    except OSError:
        return None
    for line in text.splitlines():
        key, sep, value = line.partition(":")
        if sep and key.strip().lower() == name:
            return value.strip()
    return None


def cpu_flags(cpuinfo: Path = CPUINFO) -> frozenset[str]:
    """The CPU's feature flags from /proc/cpuinfo (empty where that file does not exist)."""
    return frozenset((cpuinfo_field("flags", cpuinfo) or "").split())


@functools.cache
def _bf16_conv_error() -> str | None:
    """None when oneDNN runs bf16 convolutions natively on this CPU, else why not (one line).

    A plain ``F.conv2d`` is no test: on a CPU without the instructions small bf16 convolutions take torch's
    emulated fallback (2-3x slower than fp32) and only larger ones reach oneDNN and raise. So this asks
    oneDNN's own check and runs a tiny bf16 conv2d and conv3d through ``mkldnn_convolution`` itself."""
    import torch

    if not torch.backends.mkldnn.is_available():
        return "oneDNN (this torch is built without it)"
    supported = getattr(torch.ops.mkldnn, "_is_mkldnn_bf16_supported", None)
    try:
        if supported is not None and not supported():
            return "oneDNN's bf16 instructions"
        with torch.inference_mode():
            for dims, fmt in ((2, torch.channels_last), (3, torch.channels_last_3d)):
                x = torch.ones((1, 2) + (4,) * dims, dtype=torch.bfloat16).contiguous(memory_format=fmt)
                w = torch.ones((2, 2) + (3,) * dims, dtype=torch.bfloat16).contiguous(memory_format=fmt)
                torch.mkldnn_convolution(x, w, None, [1] * dims, [1] * dims, [1] * dims, 1)
    except RuntimeError as exc:
        return (str(exc).strip().splitlines() or ["bf16 convolution failed"])[0]
    return None


def _missing_flags(flags: frozenset[str]) -> str:
    """The AVX-512 subsets a CPU with ``flags`` lacks for bf16 convolutions, comma-separated."""
    return ", ".join([f for f in BF16_AVX512_FLAGS if f not in flags] or BF16_AVX512_FLAGS)


def cpu_bf16_missing() -> str | None:
    """None when this CPU runs bf16 convolutions; else what it lacks, in words (e.g. ``avx512bw, avx512vl``)."""
    if os.environ.get(FORCE_NO_BF16_ENV, "").strip() not in ("", "0"):
        return f"{_missing_flags(frozenset())} (simulated by {FORCE_NO_BF16_ENV}=1)"
    error = _bf16_conv_error()
    if error is None:
        return None
    flags = cpu_flags()
    return _missing_flags(flags) if flags else f"bf16 convolutions ({error})"


def bf16_missing(device) -> str | None:
    """None when ``device`` (a torch.device) runs bf16 convolutions; else what it lacks, in words."""
    import torch

    if device.type == "cuda":
        return None if torch.cuda.is_bf16_supported() else "bf16 support"
    if device.type == "cpu":
        return cpu_bf16_missing()
    return "bf16 convolutions"


def bf16_unavailable(device) -> str | None:
    """None when ``device`` runs bf16 convolutions natively; else the one line users see where a bf16 case is
    skipped, e.g. ``this CPU has no bf16 convolutions (it lacks avx512bw, avx512vl, avx512dq)``."""
    missing = bf16_missing(device)
    if missing is None:
        return None
    return f"{'this CPU' if device.type == 'cpu' else device} has no bf16 convolutions (it lacks {missing})"


def require_bf16(device, what: str = "precision=bf16") -> None:
    """SpecError (one line: the missing capability and the alternative) unless ``device`` runs bf16."""
    missing = bf16_missing(device)
    if missing is not None:
        if device.type == "cpu":
            raise SpecError(f"{what} needs bf16 convolutions (on a CPU: {'+'.join(BF16_AVX512_FLAGS)}, "
                            f"avx_ne_convert or AMX); this CPU lacks {missing}: use precision=fp32, or a GPU "
                            "(device=cuda)")
        raise SpecError(f"{what} needs bf16 convolutions; {device} lacks {missing}: use precision=fp32")


def parse_device(spec: str) -> tuple[str, int | None]:
    """``auto|cpu|cuda|cuda:K`` -> (kind, index or None); SpecError otherwise."""
    m = _DEVICE_RE.match(str(spec).strip().lower())
    if m is None or (m.group(2) is not None and m.group(1) != "cuda"):
        raise SpecError(f"device must be {DEVICE_HELP}, got {spec!r}")
    return m.group(1), None if m.group(2) is None else int(m.group(2))


def resolve_device(spec="auto"):
    """The torch.device for ``auto`` (cuda when torch sees a GPU, else cpu), ``cpu``, ``cuda`` (the current
    CUDA device, e.g. the one LOCAL_RANK selected) or ``cuda:K``. A torch.device passes through checked.
    SpecError (one line) for CUDA on a machine without it, or an index past the visible GPUs."""
    import torch

    if isinstance(spec, torch.device):
        spec = str(spec)
    kind, index = parse_device(spec)
    if kind == "cpu":
        return torch.device("cpu")
    available = torch.cuda.is_available()
    if kind == "auto":
        return torch.device("cuda", torch.cuda.current_device()) if available else torch.device("cpu")
    if not available:
        raise SpecError(f"device={spec} but torch {torch.__version__} sees no CUDA GPU "
                        f"({'built without CUDA' if torch.version.cuda is None else 'no GPU or driver visible'}); "
                        "use device=cpu or device=auto")
    count = torch.cuda.device_count()
    if index is None:
        index = torch.cuda.current_device()
    if index >= count:
        raise SpecError(f"device={spec} but only {count} CUDA GPU{'s' if count != 1 else ''} "
                        f"{'are' if count != 1 else 'is'} visible (cuda:0..cuda:{count - 1})")
    return torch.device("cuda", index)


def _new_precision_api() -> bool:
    import torch

    return hasattr(torch.backends.cuda.matmul, "fp32_precision")  # torch >= 2.9


def set_fp32_numerics(tf32: bool = False) -> None:
    """fp32 CUDA matmuls and cuDNN convolutions in IEEE fp32 (``tf32=False``, the reproduction default) or
    TF32 (``tf32=True``: 10 mantissa bits, several times faster on Ampere and later). Process-wide. On
    torch >= 2.9 through the per-backend ``fp32_precision`` flags only (mixing them with the legacy
    ``allow_tf32`` / ``set_float32_matmul_precision`` makes torch raise), else through the legacy ones."""
    import torch

    if _new_precision_api():
        mode = "tf32" if tf32 else "ieee"
        torch.backends.cuda.matmul.fp32_precision = mode
        torch.backends.cudnn.conv.fp32_precision = mode
        torch.backends.cudnn.rnn.fp32_precision = mode
    else:  # pragma: no cover - torch < 2.9
        torch.backends.cuda.matmul.allow_tf32 = tf32
        torch.backends.cudnn.allow_tf32 = tf32
        torch.set_float32_matmul_precision("high" if tf32 else "highest")


def fp32_numerics() -> str:
    """``ieee`` when fp32 CUDA matmuls and cuDNN convolutions are IEEE fp32, ``tf32`` when either may use
    TF32 (torch's own default lets cuDNN convolutions use TF32)."""
    import torch

    if _new_precision_api():
        b = torch.backends
        modes = (b.cuda.matmul.fp32_precision, b.cudnn.conv.fp32_precision)  # "none" inherits: IEEE
        return "tf32" if "tf32" in modes else "ieee"
    return "tf32" if torch.backends.cuda.matmul.allow_tf32 or torch.backends.cudnn.allow_tf32 else "ieee"


def cuda_devices() -> list[str]:
    """The visible CUDA devices as ``cuda:K`` (empty without CUDA)."""
    import torch

    return [f"cuda:{k}" for k in range(torch.cuda.device_count())] if torch.cuda.is_available() else []


__all__ = ["FORCE_NO_BF16_ENV", "DEVICE_HELP", "cpuinfo_field", "cpu_flags", "cpu_bf16_missing", "bf16_missing",
           "bf16_unavailable", "require_bf16", "parse_device", "resolve_device", "set_fp32_numerics", "fp32_numerics",
           "cuda_devices"]
