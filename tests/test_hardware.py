"""Hardware capabilities and devices (lfbench.utils.hardware): bf16 on CPUs without it, device resolution
(CUDA mocked where this machine has none), the fp32 numerics policy, the GPU memory budget, and methods and
commands that honour them."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch
from helpers import write_scene

from lfbench.cli import main
from lfbench.method.registry import create, create_from_spec
from lfbench.utils import hardware
from lfbench.utils.errors import SpecError


@pytest.fixture()
def no_bf16(monkeypatch):
    """As on an AVX2-only CPU (the machine the issue was filed from)."""
    monkeypatch.setenv(hardware.FORCE_NO_BF16_ENV, "1")


@pytest.fixture()
def two_gpus(monkeypatch):
    """torch.cuda as on a machine with two visible GPUs, the current one cuda:0 (nothing runs on them)."""
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    monkeypatch.setattr(torch.cuda, "device_count", lambda: 2)
    monkeypatch.setattr(torch.cuda, "current_device", lambda: 0)


def test_cpu_flags_are_read_from_cpuinfo(tmp_path: Path):
    info = tmp_path / "cpuinfo"
    info.write_text("processor\t: 0\nflags\t\t: fpu sse avx2 avx512f avx512bw\n\nprocessor\t: 1\n")
    assert hardware.cpu_flags(info) == {"fpu", "sse", "avx2", "avx512f", "avx512bw"}
    assert hardware.cpu_flags(tmp_path / "absent") == frozenset()
    assert hardware._missing_flags(hardware.cpu_flags(info)) == "avx512vl, avx512dq"


def test_cpuinfo_fields_are_read_from_the_first_processor(tmp_path: Path):
    info = tmp_path / "cpuinfo"
    info.write_text("processor\t: 0\nModel Name\t: Example CPU @ 2.0GHz \nvmx flags\t: ept\nflags\t\t: fpu sse\n\n"
                    "processor\t: 1\nmodel name\t: Other CPU\n")
    assert hardware.cpuinfo_field("model name", info) == "Example CPU @ 2.0GHz"
    assert hardware.cpuinfo_field("flags", info) == "fpu sse"  # not the 'vmx flags' line
    assert hardware.cpuinfo_field("bogomips", info) is None
    assert hardware.cpuinfo_field("model name", tmp_path / "absent") is None


def test_the_answer_follows_the_trial_convolution(monkeypatch):
    # What this CPU can do is decided by running a bf16 convolution, not by the flags alone (the real
    # detection: a suite run with LFBENCH_FORCE_NO_BF16=1, simulating an AVX2 CPU, must not override it here).
    monkeypatch.delenv(hardware.FORCE_NO_BF16_ENV, raising=False)
    expected = hardware._bf16_conv_error()
    assert (hardware.cpu_bf16_missing() is None) == (expected is None)
    monkeypatch.setattr(hardware, "_bf16_conv_error", lambda: "mkldnn_convolution: bf16 path needs avx512bw")
    monkeypatch.setattr(hardware, "cpu_flags", lambda: frozenset({"avx2", "avx512f"}))
    assert hardware.cpu_bf16_missing() == "avx512bw, avx512vl, avx512dq"


def test_the_real_answer_is_what_the_real_kernels_do(monkeypatch):
    # Not simulated: the answer must agree with what oneDNN does with shapes of the size SubFocal runs
    # (an AVX2 CPU runs a tiny bf16 F.conv2d through an emulation and fails only on the fused oneDNN ops real
    # shapes take, so a probe of F.conv2d said "bf16 available" there and predict ended in a traceback).
    from lfbench_methods.subfocal.fast import conv

    monkeypatch.delenv(hardware.FORCE_NO_BF16_ENV, raising=False)
    x = torch.rand(1, 16, 5, 24, 24).to(torch.bfloat16).contiguous(memory_format=torch.channels_last_3d)
    w = torch.rand(16, 16, 3, 3, 3).to(torch.bfloat16).contiguous(memory_format=torch.channels_last_3d)
    x2 = torch.rand(1, 81, 32, 32).to(torch.bfloat16).contiguous(memory_format=torch.channels_last)
    w2 = torch.rand(16, 81, 3, 3).to(torch.bfloat16).contiguous(memory_format=torch.channels_last)

    def runs() -> bool:
        try:
            with torch.inference_mode():
                conv(x, w, None, (1, 1, 1), relu=True)
                torch.mkldnn_convolution(x2, w2, None, [1, 1], [1, 1], [1, 1], 1)
        except RuntimeError:
            return False
        return True

    assert (hardware.cpu_bf16_missing() is None) == runs()
    unavailable = hardware.bf16_unavailable(torch.device("cpu"))
    assert (unavailable is None) == (hardware.cpu_bf16_missing() is None)
    if unavailable is not None:
        assert unavailable.startswith("this CPU has no bf16 convolutions (it lacks ") and "\n" not in unavailable


def test_predict_bf16_is_a_map_or_one_line_on_this_real_cpu(monkeypatch, tmp_path: Path, capsys):
    monkeypatch.delenv(hardware.FORCE_NO_BF16_ENV, raising=False)
    views = tmp_path / "views.npy"
    np.save(views, np.random.default_rng(0).random((16, 16, 81), dtype=np.float32))
    out = tmp_path / "out.npy"
    code = main(["predict", "--method", "subfocal:width=16,precision=bf16,threads=1", "--input", str(views),
                 "--out", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    if hardware.cpu_bf16_missing() is None:
        assert code == 0 and np.load(out).shape == (16, 16)
    else:
        assert code == 2 and len(err) == 1 and "needs bf16 convolutions" in err[0] and not out.exists()


def test_bf16_on_a_cpu_without_it_is_one_line_naming_the_capability_and_the_alternative(no_bf16):
    with pytest.raises(SpecError) as exc:
        hardware.require_bf16(torch.device("cpu"))
    msg = str(exc.value)
    assert "\n" not in msg and "lacks avx512bw, avx512vl, avx512dq" in msg
    assert "precision=fp32" in msg and "GPU" in msg
    # The methods refuse it when they are made, before any work.
    for spec in ("subfocal:width=16,precision=bf16", "lfattnet:precision=bf16"):
        with pytest.raises(SpecError, match="lacks avx512bw"):
            create_from_spec(spec)
    assert create_from_spec("subfocal:width=16,precision=fp32") is not None


def test_predict_bf16_on_a_cpu_without_it_exits_2_with_one_line(no_bf16, tmp_path: Path, capsys):
    views = tmp_path / "views.npy"
    np.save(views, np.random.default_rng(0).random((12, 12, 81), dtype=np.float32))
    out = tmp_path / "out.pfm"
    assert main(["predict", "--method", "subfocal:width=16,precision=bf16", "--input", str(views),
                 "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("lfbench predict: error: precision=bf16 needs bf16 convolutions")
    assert "Traceback" not in err[0] and not out.exists()


def test_infer_refuses_bf16_where_it_cannot_run(no_bf16):
    from lfbench_methods.subfocal.inference import infer
    from lfbench_methods.subfocal.network import SubFocalNet

    with pytest.raises(SpecError, match="lacks avx512bw"):
        infer(SubFocalNet(width=2, interval=1.0), torch.rand(81, 8, 8), precision="bf16")


def test_devices_resolve_and_refuse_what_is_not_there(monkeypatch):
    assert hardware.resolve_device("cpu") == torch.device("cpu")
    assert hardware.resolve_device(torch.device("cpu")) == torch.device("cpu")
    for bad in ("gpu", "cpu:1", "cuda:x", "mps"):
        with pytest.raises(SpecError, match=r"device must be auto \(CUDA when available, else CPU\), cpu, cuda"):
            hardware.resolve_device(bad)
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    assert hardware.resolve_device("auto") == torch.device("cpu")
    for spec in ("cuda", "cuda:0"):
        with pytest.raises(SpecError, match=f"device={spec} but torch .* sees no CUDA GPU"):
            hardware.resolve_device(spec)
    assert hardware.cuda_devices() == []


def test_devices_with_two_gpus(two_gpus):
    assert hardware.resolve_device("auto") == torch.device("cuda", 0)
    assert hardware.resolve_device("cuda") == torch.device("cuda", 0)
    assert hardware.resolve_device("CUDA:1") == torch.device("cuda", 1)
    with pytest.raises(SpecError, match=r"device=cuda:2 but only 2 CUDA GPUs are visible \(cuda:0..cuda:1\)"):
        hardware.resolve_device("cuda:2")
    assert hardware.cuda_devices() == ["cuda:0", "cuda:1"]


def test_a_method_on_a_missing_gpu_is_refused_when_made(monkeypatch, capsys, tmp_path: Path):
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    for spec in ("subfocal:width=16,device=cuda", "lfattnet:device=cuda:1", "planesweep:device=cuda"):
        with pytest.raises(SpecError, match="sees no CUDA GPU"):
            create_from_spec(spec)
    # --device fills the methods that have a device parameter, and stays out of their labels.
    m = create_from_spec("planesweep:interval=0.5", {"device": "cpu"})
    assert m.device == torch.device("cpu") and m.label == "planesweep:interval=0.5"
    assert create_from_spec("gt", {"device": "cuda"}).label == "gt"  # no device parameter: not passed
    assert create_from_spec("planesweep:device=cpu", {"device": "cuda"}).device.type == "cpu"  # the spec wins
    write_scene(tmp_path / "data", size=24)  # a real data root: the device is what is refused
    assert main(["evaluate", "--data", str(tmp_path / "data"), "--method", "planesweep", "--device", "cuda:0",
                 "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "device=cuda:0" in err[0] and not (tmp_path / "out").exists()


def test_fp32_means_ieee_unless_tf32_is_asked_for():
    before = hardware.fp32_numerics()
    try:
        hardware.set_fp32_numerics(tf32=True)
        assert hardware.fp32_numerics() == "tf32"
        hardware.set_fp32_numerics(tf32=False)
        assert hardware.fp32_numerics() == "ieee"
        if hasattr(torch.backends.cuda.matmul, "fp32_precision"):
            assert torch.backends.cuda.matmul.fp32_precision == "ieee"
            assert torch.backends.cudnn.conv.fp32_precision == "ieee"
    finally:
        hardware.set_fp32_numerics(tf32=before == "tf32")


def test_the_gpu_budget_is_its_free_memory_plus_torchs_unused_cache(monkeypatch):
    from lfbench_methods.subfocal import inference
    from lfbench_methods.subfocal.network import SubFocalNet

    cuda = torch.device("cuda", 0)
    monkeypatch.setattr(torch.cuda, "mem_get_info", lambda device=None: (int(30e9), int(80e9)))
    monkeypatch.setattr(torch.cuda, "memory_reserved", lambda device=None: int(6e9))
    monkeypatch.setattr(torch.cuda, "memory_allocated", lambda device=None: int(4e9))
    assert inference.memory_budget_gb(cuda) == pytest.approx(32.0)  # 30 free + (6 - 4) cached, unused
    assert inference.memory_budget_gb(cuda, 8.0) == 8.0 and inference.memory_budget_gb(cuda, 50.0) == 32.0
    assert inference.memory_budget_gb(torch.device("cpu")) == inference.CPU_BUDGET_GB == 4.0
    assert inference.memory_budget_gb(None, 2.5) == 2.5
    # The planner follows the budget: the paper network at interval 0.5 on 512x512 fits whole in 32 GB on a GPU
    # (without oneDNN's in-place add: three live activations), not in 4 GB.
    paper = SubFocalNet(interval=0.5)
    assert inference.plan_tiles(paper, 512, 512, max_memory_gb=32.0, device=cuda) == (512, 512)
    assert inference.plan_tiles(paper, 512, 512, max_memory_gb=4.0, device=cuda) != (512, 512)
    three = inference.estimate_tile_bytes(paper, 64, 64, device=cuda)
    assert three >= inference.estimate_tile_bytes(paper, 64, 64, device="cpu")


def test_planesweep_makes_every_tensor_on_the_views_device():
    """Every tensor factory call in the sweep names a device (or copies one with *_like): on a GPU nothing is
    allocated on the CPU behind the views' back."""
    from lfbench_methods.planesweep.estimator import estimate
    from torch.overrides import TorchFunctionMode

    from lfbench.data.shift import angular_offsets, disparity_grid

    factories = {torch.arange, torch.empty, torch.zeros, torch.ones, torch.full, torch.tensor, torch.linspace,
                 torch.rand, torch.randn, torch.fft.fftfreq, torch.fft.rfftfreq, torch.eye}
    unplaced = []

    class Watch(TorchFunctionMode):
        def __torch_function__(self, func, types, args=(), kwargs=None):
            kwargs = kwargs or {}
            if func in factories and "device" not in kwargs:
                unplaced.append(func.__name__)
            return func(*args, **kwargs)

    views = torch.rand(81, 12, 12, generator=torch.Generator().manual_seed(0))
    offsets, grid = angular_offsets(9, 9), disparity_grid(-1, 1, 0.5)
    for mode in ("bilinear", "nearest", "phase"):
        with torch.inference_mode(), Watch():
            out = estimate(views, offsets, grid, 0.5, interpolation=mode, arm_length=3)
        assert all(t.device == views.device for t in out)
    assert unplaced == []
    assert create("planesweep", device="cpu").predict is not None
