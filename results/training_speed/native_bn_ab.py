"""A/B of the view batch norm's two CPU kernels inside one width-16 training step (batch 4, 32x32 patches, L1,
Adam, 1 thread): ATen's batch norm per view group for >= 16 channels (NATIVE_BN_CHANNELS = 16, the default)
against the folded elementwise ops everywhere. Three interleaved rounds of 3 timed steps (CPU seconds per
step, after one warm-up step each); prints every round and the best of each.

    python results/training_speed/native_bn_ab.py                      # the CPU's own kernels
    ATEN_CPU_CAPABILITY=avx2 ONEDNN_MAX_CPU_ISA=AVX2 python results/training_speed/native_bn_ab.py
"""

import time

import lfbench_methods.subfocal.network as network
import torch

from lfbench.utils.malloc import retain_freed_memory

torch.set_num_threads(1)
retain_freed_memory()
torch.manual_seed(0)
net = network.SubFocalNet(interval=0.5, width=16).train()
opt = torch.optim.Adam(net.parameters(), 1e-4)
views = torch.rand(4, 81, 32, 32)


def step() -> None:
    opt.zero_grad(set_to_none=True)
    disparity, _ = net(views)
    disparity.abs().mean().backward()
    opt.step()


rounds: dict[str, list[float]] = {"native": [], "folded": []}
for _ in range(3):
    for name, channels in (("native", 16), ("folded", 10**9)):
        network.NATIVE_BN_CHANNELS = channels
        step()
        start = time.process_time()
        for _ in range(3):
            step()
        rounds[name].append((time.process_time() - start) / 3)
        print(name, round(rounds[name][-1], 3), flush=True)
print({name: round(min(values), 3) for name, values in rounds.items()})
