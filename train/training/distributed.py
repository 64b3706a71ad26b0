"""Data-parallel training across processes (``torchrun``): gloo on CPU, nccl on GPU.

Every process draws the same permutation of the examples each epoch; each global batch is cut
into one equal slice per process, and DistributedDataParallel averages the gradients, so the
step equals one process's step on the whole global batch. Only rank 0 writes; metrics are
summed as (sum, count) across processes so each example counts once.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import torch
import torch.distributed as dist


@dataclass(frozen=True)
class DistContext:
    """Where this process stands: rank among world processes (1 when not distributed)."""

    rank: int = 0
    world: int = 1

    @property
    def main(self) -> bool:
        return self.rank == 0

    def my_slice(self, batch: torch.Tensor) -> torch.Tensor:
        """This process's equal part of a global batch (rows ``rank::world`` would reorder)."""
        if self.world == 1:
            return batch
        return torch.tensor_split(batch, self.world)[self.rank]

    def total(self, values: torch.Tensor) -> torch.Tensor:
        """Sum of ``values`` over every process (itself when alone)."""
        if self.world > 1:
            values = values.clone()
            dist.all_reduce(values)
        return values


def from_env(device: torch.device) -> DistContext:
    """Join the process group torchrun describes in the environment (WORLD_SIZE > 1)."""
    world = int(os.environ.get("WORLD_SIZE", "1"))
    if world == 1:
        return DistContext()
    if not dist.is_initialized():
        dist.init_process_group("nccl" if device.type == "cuda" else "gloo")
    return DistContext(dist.get_rank(), dist.get_world_size())
