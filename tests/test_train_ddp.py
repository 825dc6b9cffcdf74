"""Data-parallel training (lfmbench.distributed): the ranks share every batch without double counting, train one
model (weights equal on every rank), rank 0 writes the checkpoint, and a resumed run ends where an uninterrupted
one does. Two real processes, gloo on the CPU."""
from __future__ import annotations

import os
import socket

import pytest
import torch

from lfmbench import distributed as D
from lfmbench.datasets.device import epoch_order

#: A U-Net small enough for the 16 x 24 px test corpus (as tests/baselines/test_unet.py); batch 3 over the train
#: split's samples leaves a short last batch, so one rank gets a zero-weight part.
TINY = {"model": {"base_channels": 2, "depth": 1},
        "train": {"epochs": 2, "batch_size": 3, "crop": 8, "samples_per_scene": 4, "workers": 0, "lr": 1e-2}}


def test_ranks_share_every_batch_once():
    for n, b, world in ((10, 4, 2), (7, 3, 2), (5, 5, 3), (4, 1, 2), (9, 2, 4)):
        for epoch in (0, 1):
            one = epoch_order(n, 3, epoch).tolist()  # what one process sees, batch after batch
            parts = []
            for r in range(world):
                s = D.RankBatchSampler(n, b, 3, r, world)
                s.set_epoch(epoch)
                parts.append(list(s))
            assert all(len(p) == -(-n // b) for p in parts)  # every rank takes every step (DDP needs it)
            for k in range(len(parts[0])):
                counted = [i for p in parts for (e, i, w) in p[k] if w > 0]
                assert counted == one[k * b:(k + 1) * b]  # the global batch, each sample once, in order
                w = [p[k][0][2] for p in parts]
                sizes = [sum(1 for (_, _, wt) in p[k] if wt > 0) for p in parts]
                batch = len(one[k * b:(k + 1) * b])
                # weights b_r N / b: the ranks' weighted mean of per-rank means is the global mean
                assert sum(wr * sz / max(sz, 1) for wr, sz in zip(w, sizes)) == pytest.approx(world)
                assert all(abs(wr - sz * world / batch) < 1e-12 for wr, sz in zip(w, sizes))


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _rank(rank: int, world: int, port: int, corpus, cfg_path, tmp) -> None:
    os.environ.update(RANK=str(rank), LOCAL_RANK=str(rank), WORLD_SIZE=str(world), MASTER_ADDR="127.0.0.1",
                      MASTER_PORT=str(port))
    torch.set_num_threads(1)
    import torch.distributed as dist

    from lfmbench import train as T

    cfg = T.load_config("unet", cfg_path)
    seen: list = []
    get = D.RankIndexed.__getitem__

    def spy(self, key):
        seen.append((key[0], key[1], key[2]))
        return get(self, key)

    D.RankIndexed.__getitem__ = spy
    kw = dict(progress=False, log=None)
    a, _ = T.train("unet", corpus, tmp / "a.pt", cfg, epochs=2, **kw)        # uninterrupted
    seen_a = list(seen)
    T.train("unet", corpus, tmp / "b.pt", cfg, epochs=2, max_steps=2, **kw)  # stopped after epoch 1 ...
    b, _ = T.train("unet", corpus, tmp / "b.pt", cfg, epochs=2, **kw)        # ... and resumed
    torch.save({"a": a.state_dict(), "b": b.state_dict(), "seen": seen_a}, tmp / f"rank{rank}.pt")
    dist.destroy_process_group()


@pytest.mark.slow
@pytest.mark.integration
def test_two_gloo_ranks_train_one_model_and_resume(corpus, tmp_path):
    import yaml

    from lfmbench.baselines import unet as U
    from lfmbench.datasets.loading import make_dataset

    cfg_path = tmp_path / "tiny.yaml"
    cfg_path.write_text(yaml.safe_dump(TINY))
    torch.multiprocessing.start_processes(_rank, args=(2, _free_port(), corpus, cfg_path, tmp_path), nprocs=2,
                                          start_method="spawn")  # fork after torch ran here can hang a child
    r0, r1 = (torch.load(tmp_path / f"rank{r}.pt") for r in (0, 1))
    for k in r0["a"]:
        assert torch.equal(r0["a"][k], r1["a"][k])  # one model: the same weights on both ranks, bit for bit
        # resume: the same steps in the same order; a tolerance for a reduction order that may differ between runs
        torch.testing.assert_close(r0["b"][k], r0["a"][k], rtol=1e-6, atol=1e-7)
    ck = U.read_checkpoint(tmp_path / "a.pt")  # written by rank 0, after the last epoch
    assert ck["epochs_done"] == 2 and all(torch.equal(ck["state_dict"][k], r0["a"][k]) for k in r0["a"])
    assert not list(tmp_path.glob(".lfmtmp-*"))
    # the same samples as one process: in each epoch of the first run, every sample once over the two ranks
    n = len(make_dataset(corpus, "train", seed=0, crop=8, samples_per_scene=4, frames=3))
    assert n % 3 == 1 and -(-n // 3) == 2  # 2 steps an epoch; the last batch holds one sample: rank 1's part of
    #                                        it is a zero-weight copy
    for ep in (0, 1):
        counted = sorted(i for r in (r0, r1) for (e, i, w) in r["seen"] if e == ep and w > 0)
        assert counted == list(range(n))
        assert sum(1 for r in (r0, r1) for (e, i, w) in r["seen"] if e == ep and w == 0) == 1
