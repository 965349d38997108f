"""Batches of a training stage, made ahead of the step that uses them: a prefetch thread
(:class:`Prefetcher`) or DataLoader worker processes (:class:`LoaderBatches`); both give the same batches,
a pure function of (seed, stage, step, sample index)."""

from __future__ import annotations

from concurrent.futures import Future, ThreadPoolExecutor

import numpy as np
import torch

from lfbench.training.config import TrainConfig
from lfbench.training.data import PatchSampler


class Prefetcher:
    """Batches of one rank for steps start..end-1, computed ``depth`` steps ahead in a thread."""

    def __init__(self, sampler: PatchSampler, seed: int, stage: int, start: int, end: int,
                 first_index: int, count: int, depth: int) -> None:
        self.args = (sampler, seed, stage, first_index, count)
        self.end, self.depth = end, depth
        self.pool = ThreadPoolExecutor(max_workers=1) if depth > 0 else None
        self.pending: dict[int, Future] = {}
        self.next = start

    def _make(self, step: int):
        sampler, seed, stage, first, count = self.args
        return sampler.sample(seed, stage, step, first, count)

    def get(self, step: int) -> tuple[np.ndarray, np.ndarray]:
        if self.pool is None:
            return self._make(step)
        while self.next < min(step + self.depth + 1, self.end):
            self.pending[self.next] = self.pool.submit(self._make, self.next)
            self.next += 1
        fut = self.pending.pop(step, None)
        return fut.result() if fut is not None else self._make(step)

    def close(self) -> None:
        if self.pool is not None:
            for f in self.pending.values():
                f.cancel()
            self.pool.shutdown(wait=True)


class _StepBatches(torch.utils.data.Dataset):
    """Item i: the batch of step start + i (samples first..first+count-1 of its global batch) as tensors."""

    def __init__(self, sampler: PatchSampler, seed: int, stage: int, start: int, end: int, first: int,
                 count: int) -> None:
        self.args, self.start, self.end = (seed, stage, first, count), start, end
        self.sampler = sampler

    def __len__(self) -> int:
        return max(0, self.end - self.start)

    def __getitem__(self, i: int) -> tuple[torch.Tensor, torch.Tensor]:
        seed, stage, first, count = self.args
        views, target = self.sampler.sample(seed, stage, self.start + i, first, count)
        return torch.from_numpy(views), torch.from_numpy(target)


class LoaderBatches:
    """Batches of steps start..end-1 made by ``workers`` DataLoader processes, in step order (the same interface
    as :class:`Prefetcher`). Every sample's generator is derived from (seed, stage, step, index), so the
    batches are the same for any number of workers, and a resumed run continues with the same batches."""

    def __init__(self, sampler: PatchSampler, seed: int, stage: int, start: int, end: int, first_index: int,
                 count: int, workers: int, pin_memory: bool = False, depth: int = 2) -> None:
        data = _StepBatches(sampler, seed, stage, start, end, first_index, count)
        self.loader = torch.utils.data.DataLoader(data, batch_size=None, shuffle=False, num_workers=workers,
                                                  pin_memory=pin_memory, prefetch_factor=max(2, depth))
        self.it = iter(self.loader)
        self.next = start

    def get(self, step: int) -> tuple[torch.Tensor, torch.Tensor]:
        if step != self.next:
            raise RuntimeError(f"batches are made in order: asked for step {step}, next is {self.next}")
        self.next += 1
        return next(self.it)

    def close(self) -> None:
        self.it = None  # the iterator's workers stop when it is released


def batch_source(sampler: PatchSampler, cfg: TrainConfig, stage: int, start: int, end: int, first_index: int,
                 count: int, pin_memory: bool = False):
    """The batches of a stage: DataLoader workers when training.workers > 0, else the prefetch thread."""
    tc = cfg.training
    if tc.workers > 0:
        return LoaderBatches(sampler, cfg.seed, stage, start, end, first_index, count, tc.workers, pin_memory,
                             tc.prefetch)
    return Prefetcher(sampler, cfg.seed, stage, start, end, first_index, count, tc.prefetch)


__all__ = ["LoaderBatches", "Prefetcher", "batch_source"]
