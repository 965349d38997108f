"""torch.distributed set-up for data-parallel training, read from torchrun's or SLURM's environment.

``torchrun --nproc-per-node K -m lfbench train CONFIG.toml`` starts K processes with RANK,
WORLD_SIZE, LOCAL_RANK, MASTER_ADDR and MASTER_PORT set; each joins a process group (NCCL on
GPUs, gloo on CPU). Under ``srun`` (one task per GPU, no torchrun) the rank, world size and local rank
come from SLURM_PROCID, SLURM_STEP_NUM_TASKS (or SLURM_NTASKS) and SLURM_LOCALID, with MASTER_ADDR and
MASTER_PORT from the job script. Without any of these, training runs in a single process.

Before training, every rank must resume from the same position (:func:`agree_on_resume`): a rank that
sees another checkpoint (or none: a node without the shared file system) stops every rank with one
error line instead of a silent hang in the first collective.
"""

from __future__ import annotations

import functools
import os
from dataclasses import dataclass, field
from datetime import timedelta

import torch
import torch.distributed as dist

from lfbench.utils.errors import LFBenchError, SpecError
from lfbench.utils.hardware import parse_device
from lfbench.utils.hardware import resolve_device as hardware_device


@dataclass
class DistContext:
    """Where this process stands: rank, world size, device and the process group's backend."""

    rank: int = 0
    world_size: int = 1
    local_rank: int = 0
    device: torch.device = field(default_factory=lambda: torch.device("cpu"))
    backend: str | None = None

    @property
    def enabled(self) -> bool:
        return self.world_size > 1

    @property
    def is_main(self) -> bool:
        return self.rank == 0

    def barrier(self) -> None:
        if self.enabled:
            if self.backend == "nccl":
                dist.barrier(device_ids=[self.device.index or 0])
            else:
                dist.barrier()

    def mean(self, value: float) -> float:
        """The average of ``value`` over all ranks."""
        if not self.enabled:
            return float(value)
        t = torch.tensor([float(value)], dtype=torch.float64, device=self.device)
        dist.all_reduce(t, op=dist.ReduceOp.SUM)
        return float(t.item()) / self.world_size

    def any(self, flag: bool) -> bool:
        """True on every rank if ``flag`` is True on any rank."""
        if not self.enabled:
            return bool(flag)
        t = torch.tensor([1 if flag else 0], dtype=torch.int32, device=self.device)
        dist.all_reduce(t, op=dist.ReduceOp.MAX)
        return bool(t.item())

    def gather(self, obj) -> list:
        """Every rank's ``obj`` (picklable), in rank order, on every rank."""
        if not self.enabled:
            return [obj]
        out: list = [None] * self.world_size
        dist.all_gather_object(out, obj)
        return out

    def broadcast_buffers(self, module: torch.nn.Module) -> None:
        """Copy rank 0's buffers (BatchNorm running statistics) to every rank.

        DistributedDataParallel broadcasts them at the start of each forward, so after the last
        step each rank still holds its own last update."""
        if self.enabled:
            for b in module.buffers():
                dist.broadcast(b.data, src=0)

    def close(self) -> None:
        if self.enabled and dist.is_initialized():
            dist.destroy_process_group()


def match_grad_strides(module: torch.nn.Module) -> list[torch.utils.hooks.RemovableHandle]:
    """Give each parameter's gradient the parameter's own strides where the two differ only in dimensions of size 1.

    A 1x1 convolution's weight (O, I, 1, 1) in channels-last memory and its contiguous gradient (the network
    uses it as a matrix) address the same elements in the same order, but their strides differ in the size-1
    dimensions. Autograd's layout contract ignores those dimensions, DistributedDataParallel compares every stride:
    it warned once ("Grad strides do not match bucket view strides") and copied such gradients each step. The hook
    returns a view with the parameter's strides (as they are now: when DDP is built): no copy, the same values. A
    gradient of any other layout is left as it is. Returns the hooks' handles (remove them before a new DDP wraps the
    module: each stage builds its own)."""
    return [param.register_hook(functools.partial(_restride, shape=param.shape, stride=param.stride()))
            for param in module.parameters() if param.requires_grad and param.layout == torch.strided]


def _restride(grad: torch.Tensor, *, shape: torch.Size, stride: tuple[int, ...]) -> torch.Tensor | None:
    """``grad`` viewed with ``stride`` when it differs from it only where ``shape`` is 1, else None (unchanged)."""
    if grad.layout != torch.strided or grad.shape != shape or grad.stride() == stride:
        return None
    if any(n != 1 and a != b for n, a, b in zip(shape, grad.stride(), stride, strict=True)):
        return None
    return grad.as_strided(shape, stride, grad.storage_offset())


def resolve_device(preference: str, local_rank: int = 0) -> torch.device:
    """'auto' / 'cuda' -> this process's GPU (local rank modulo the visible GPUs) when CUDA is available,
    else (auto) the CPU; 'cpu'; 'cuda:K'. SpecError (lfbench.utils.hardware) for a device this machine lacks."""
    kind, index = parse_device(preference)
    if kind in ("auto", "cuda") and index is None and torch.cuda.is_available():
        return torch.device("cuda", local_rank % torch.cuda.device_count())
    return hardware_device(preference)


def launch_env(environ=None) -> tuple[int, int, int, str]:
    """(world size, rank, local rank, launcher): torchrun's WORLD_SIZE / RANK / LOCAL_RANK; else, inside an
    ``srun`` step of several tasks (SLURM_STEP_ID set), SLURM_STEP_NUM_TASKS (or SLURM_NTASKS) /
    SLURM_PROCID / SLURM_LOCALID; else a single process. (A batch script's own shell also has SLURM_NTASKS
    but no SLURM_STEP_ID: it is one process, not a task of a step.)"""
    env = os.environ if environ is None else environ
    if "WORLD_SIZE" in env:
        rank = int(env.get("RANK", "0"))
        return int(env["WORLD_SIZE"]), rank, int(env.get("LOCAL_RANK", str(rank))), "torchrun"
    tasks = env.get("SLURM_STEP_NUM_TASKS") or env.get("SLURM_NTASKS")
    if tasks and int(tasks) > 1 and ("SLURM_STEP_ID" in env or "SLURM_STEPID" in env):
        rank = int(env.get("SLURM_PROCID", "0"))
        return int(tasks), rank, int(env.get("SLURM_LOCALID", "0")), "slurm"
    return 1, 0, 0, "none"


def agree_on_resume(ctx: DistContext, position) -> None:
    """Stop every rank with one error unless all resume from the same ``position`` (e.g. (stage, step,
    global step), or None for a fresh start). A position that is an LFBenchError (this rank could not read
    its checkpoint) is raised on every rank."""
    if not ctx.enabled:
        if isinstance(position, LFBenchError):
            raise position
        return
    seen = ctx.gather(str(position) if isinstance(position, LFBenchError) else position)
    errors = [(r, p) for r, p in enumerate(seen) if isinstance(p, str)]
    if errors:
        rank, msg = errors[0]
        raise LFBenchError(f"rank {rank} could not resume: {msg}")
    if any(p != seen[0] for p in seen):
        where = ", ".join(f"rank {r}: " + ("fresh start" if p is None else
                                           f"stage {p[0] + 1} step {p[1]} (global {p[2]})") for r, p in enumerate(seen))
        raise LFBenchError(f"the ranks would resume from different checkpoints ({where}); every node must see the "
                           "same OUT/checkpoint.pt (a shared file system), or start a new --out folder")


def setup(device: str = "auto", timeout_s: float = 1800.0) -> DistContext:
    """Join the process group described by the environment (torchrun's or an srun step's; or none: a single
    process)."""
    world, rank, local, launcher = launch_env()
    if launcher == "slurm" and not (os.environ.get("MASTER_ADDR") and os.environ.get("MASTER_PORT")):
        raise SpecError("srun started several tasks but MASTER_ADDR / MASTER_PORT are not set; in the job script: "
                        "export MASTER_ADDR=$(scontrol show hostnames $SLURM_JOB_NODELIST | head -n 1) "
                        "MASTER_PORT=29500 (or start the tasks with torchrun)")
    dev = resolve_device(device, local)
    if dev.type == "cuda":
        torch.cuda.set_device(dev)
    if world <= 1:
        return DistContext(device=dev)
    backend = "nccl" if dev.type == "cuda" else "gloo"
    if not dist.is_initialized():
        dist.init_process_group(backend=backend, init_method="env://", rank=rank, world_size=world,
                                timeout=timedelta(seconds=timeout_s))
    return DistContext(rank=rank, world_size=world, local_rank=local, device=dev, backend=backend)
