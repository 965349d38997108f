"""GPU profile (not committed): SubFocal training-step rates and top CUDA ops, inference seconds by size."""
import json, sys, time
from pathlib import Path
import torch
from lfbench_methods.subfocal.network import SubFocalNet
from lfbench_methods.subfocal.inference import infer

dev = torch.device(sys.argv[1]); out = Path(sys.argv[2]); budget = float(sys.argv[3])
T0 = time.perf_counter()
torch.backends.cudnn.benchmark = True
res = {"device": str(dev), "torch": torch.__version__}
def sync():
    if dev.type == "cuda":
        torch.cuda.synchronize()
def save():
    (out / "prof.json").write_text(json.dumps(res, indent=2))
def train_rate(width, batch, n=20, profile=False):
    torch.manual_seed(0)
    net = SubFocalNet(interval=0.5, width=width).to(dev).train()
    opt = torch.optim.Adam(net.parameters(), 1e-4)
    v = torch.rand(batch, 81, 32, 32, device=dev)
    def step():
        opt.zero_grad(set_to_none=True)
        d, p = net(v)
        d.abs().mean().backward()
        opt.step()
    for _ in range(5):
        step()
    sync(); t = time.perf_counter()
    for _ in range(n):
        step()
    sync(); rate = n / (time.perf_counter() - t)
    if profile:
        from torch.profiler import ProfilerActivity, profile as prof
        acts = [ProfilerActivity.CPU] + ([ProfilerActivity.CUDA] if dev.type == "cuda" else [])
        with prof(activities=acts) as p:
            for _ in range(3):
                step()
            sync()
        key = "cuda_time_total" if dev.type == "cuda" else "cpu_time_total"
        (out / f"profile_w{width}_b{batch}.txt").write_text(
            p.key_averages().table(sort_by=key, row_limit=30) + "\n\nby CPU time\n" +
            p.key_averages().table(sort_by="cpu_time_total", row_limit=15))
    return rate
QUICK = len(sys.argv) > 4
TRAIN = [(4, 2, True), (4, 1, False)] if QUICK else [(16, 32, True), (16, 4, False), (16, 128, False), (150, 32, False)]
for width, batch, profile in TRAIN:
    if time.perf_counter() - T0 > budget * 0.5:
        break
    try:
        res[f"train_w{width}_b{batch}_steps_per_s"] = train_rate(width, batch, n=2 if QUICK else (20 if width == 16 else 5), profile=profile)
    except Exception as e:  # noqa
        res[f"train_w{width}_b{batch}_error"] = repr(e)[:300]
    print(res, flush=True); save()
from lfbench_methods.subfocal.keras_import import build_from_checkpoint
INFER = [(16, 32, 0.5), (8, 32, 0.5)] if QUICK else [(16, 512, 0.5), (150, 128, 0.5), (150, 256, 0.5), (150, 512, 0.5)]
for width, size, interval in INFER:
    if time.perf_counter() - T0 > budget * 0.75:
        break
    try:
        torch.manual_seed(0)
        net = (build_from_checkpoint(Path("methods/weights/subfocal_small.pt")) if width == 16 else
               SubFocalNet(interval=interval, width=width)).eval().to(dev)
        views = torch.rand((1, 81, size, size), generator=torch.Generator().manual_seed(0))
        for precision in ("fp32", "bf16"):
            infer(net, views[..., :min(64, size), :min(64, size)], precision=precision, max_memory_gb=None)
            sync(); t = time.perf_counter()
            infer(net, views, precision=precision, max_memory_gb=None)
            sync(); res[f"infer_w{width}_{size}px_i{interval}_{precision}_s"] = time.perf_counter() - t
            print(res, flush=True); save()
    except Exception as e:  # noqa
        res[f"infer_w{width}_{size}_error"] = repr(e)[:300]
save()
