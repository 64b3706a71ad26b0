"""Data-parallel training: two CPU processes (gloo) take the same steps as one process with the
same global batch."""

from __future__ import annotations

import os
import socket
from pathlib import Path

import pytest
import torch
import torch.distributed as dist
import torch.multiprocessing as mp
from helpers.cgnn_data import dent_fold

from train.model.cgnn import CGNN
from train.model.config import CGNNConfig
from train.training.checkpoint import load_checkpoint
from train.training.train_params import TrainInputs, TrainOptions, TrainParams
from train.training.train_stage import run_train

SMALL = CGNNConfig(edge_widths=((16, 16),) * 3, disp_widths=(32,), force_widths=(16, 8, 8))
OPTS = TrainOptions(epochs=1, batch=6, lr=3e-3)


def _worker(rank: int, world: int, port: int, data: Path, splits: Path, out: Path) -> None:
    os.environ.update(RANK=str(rank), WORLD_SIZE=str(world), MASTER_ADDR="127.0.0.1",
                      MASTER_PORT=str(port))
    torch.set_num_threads(1)
    try:
        run_train(TrainInputs(data, splits), out, TrainParams(OPTS, SMALL, "cpu"))
    finally:
        dist.destroy_process_group()


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.skipif(not dist.is_available() or not dist.is_gloo_available(),
                    reason="torch.distributed with gloo is not available")
def test_two_processes_take_the_steps_of_one(tmp_path) -> None:
    data, splits = dent_fold(tmp_path, folds=1)
    mp.spawn(_worker, args=(2, _free_port(), data, splits, tmp_path / "ddp"), nprocs=2)
    run_train(TrainInputs(data, splits), tmp_path / "one", TrainParams(OPTS, SMALL, "cpu"))
    a = load_checkpoint(tmp_path / "ddp" / "last.pt")["model"]
    b = load_checkpoint(tmp_path / "one" / "last.pt")["model"]
    for k in a:
        torch.testing.assert_close(a[k], b[k], atol=1e-5, rtol=1e-4)
    torch.manual_seed(OPTS.seed)
    start = CGNN(SMALL).state_dict()                  # the weights both runs started from
    assert max(float((a[k] - start[k]).abs().max()) for k in a) > 1e-3   # they did train
