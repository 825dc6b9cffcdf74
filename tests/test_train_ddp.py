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


def test_rank_step_sizes_cover_every_sample_once_in_global_batches():
    """The device path's steps (rank_step_sizes): every global batch but the last holds batch_size samples, each
    rank gives its samples once an epoch, in proportion; the shares of rank_scenes are disjoint and the split."""
    for counts, b in (([8, 4], 3), ([6, 6], 4), ([5, 0 + 1, 3], 2), ([2, 2], 8), ([3, 4], 1)):
        sizes = D.rank_step_sizes(counts, b)
        n = sum(counts)
        assert len(sizes) == -(-n // b)  # the steps of one process
        assert [sum(row) for row in sizes] == [min(b, n - k * b) for k in range(len(sizes))]
        assert [sum(row[r] for row in sizes) for r in range(len(counts))] == counts
        for k in range(1, len(sizes)):  # in proportion: after k steps rank r gave about k b n_r / n samples
            for r, c in enumerate(counts):
                assert abs(sum(row[r] for row in sizes[:k]) - k * b * c / n) <= 1
    sids = [f"s{i}" for i in range(7)]
    shares = [D.rank_scenes(sids, r, 3) for r in range(3)]
    assert sorted(s for sh in shares for s in sh) == sids and sum(map(len, shares)) == 7
    with pytest.raises(ValueError, match="2 scene\\(s\\) for 3 torchrun ranks"):
        D.rank_scenes(sids[:2], 0, 3)


@pytest.mark.slow
def test_device_ranks_hold_disjoint_scenes_and_serve_the_split_once(corpus):
    """RankDeviceBatches of 2 ranks (built here in one process; no collective is involved): each holds only its
    scenes resident, serves only their samples, and the two serve every sample of the split once an epoch, in
    global batches of batch_size; a different epoch is a different order."""
    from lfmbench.datasets.device import DeviceBatches
    from lfmbench.datasets.loading import make_dataset

    # optics off: the layers without the PSF convolution (most of the time here); the sharding does not depend on it
    ds = make_dataset(corpus, "all", seed=0, crop=8, samples_per_scene=2, frames=3, noise_streams="counter",
                      optics=False)
    ranks = [D.RankDeviceBatches(ds, 4, "cpu", rank=r, world=2, seed=1) for r in (0, 1)]

    def served(rb, epoch):
        rb.set_epoch(epoch)
        got, orig = [], DeviceBatches.batch
        DeviceBatches.batch = lambda self, idx: (got.append(list(idx)), orig(self, idx))[1]
        try:
            ws = [b[D.LOSS_WEIGHT] for b in rb]
        finally:
            DeviceBatches.batch = orig
        return rb, got, ws

    sps = ds.samples_per_scene
    for epoch in (0, 1):
        (r0, g0, w0), (r1, g1, w1) = served(ranks[0], epoch), served(ranks[1], epoch)
        assert set(r0.resident.scene_ids).isdisjoint(r1.resident.scene_ids)
        assert sorted(r0.resident.scene_ids + r1.resident.scene_ids) == sorted(ds.scene_ids)
        for rb, got in ((r0, g0), (r1, g1)):  # only samples of its own scenes
            assert {ds.scene_ids[i // sps] for b in got for i in b} <= set(rb.resident.scene_ids)
        assert len(g0) == len(g1) == -(-len(ds) // 4)  # the same number of steps on both ranks (DDP needs it)
        counted = sorted(i for g, w in ((g0, w0), (g1, w1)) for b, wt in zip(g, w) if wt > 0 for i in b)
        assert counted == list(range(len(ds)))
        for k in range(len(g0)):  # weights b_r N / b of the step's global batch
            sizes = [len(g[k]) if w[k] > 0 else 0 for g, w in ((g0, w0), (g1, w1))]
            assert w0[k] == pytest.approx(sizes[0] * 2 / sum(sizes))
            assert w1[k] == pytest.approx(sizes[1] * 2 / sum(sizes))
        if epoch == 0:
            first = g0
    assert g0 != first  # epoch 1: another order


def _device_rank(rank: int, world: int, port: int, corpus, cfg_path, tmp) -> None:
    os.environ.update(RANK=str(rank), LOCAL_RANK=str(rank), WORLD_SIZE=str(world), MASTER_ADDR="127.0.0.1",
                      MASTER_PORT=str(port))
    torch.set_num_threads(1)
    import torch.distributed as dist

    from lfmbench import train as T
    from lfmbench.datasets.device import DeviceBatches

    cfg = T.load_config("unet", cfg_path)
    seen: list = []
    orig_batch, orig_init = DeviceBatches.batch, D.RankDeviceBatches.__init__
    held: list = []

    def spy_batch(self, idx):
        seen.append((self.epoch, [int(i) for i in idx]))
        return orig_batch(self, idx)

    def spy_init(self, *a, **kw):
        orig_init(self, *a, **kw)
        held.append(list(self.resident.scene_ids))

    DeviceBatches.batch, D.RankDeviceBatches.__init__ = spy_batch, spy_init
    weights = []
    orig_iter = D.RankDeviceBatches._batches

    def spy_iter(self):
        for b in orig_iter(self):
            weights.append(b[D.LOSS_WEIGHT])
            yield b

    D.RankDeviceBatches._batches = spy_iter
    m, _ = T.train("unet", corpus, tmp / "d.pt", cfg, epochs=2, device="cpu", data="device", progress=False, log=None)
    torch.save({"w": m.state_dict(), "seen": seen, "held": held, "weights": weights}, tmp / f"dev{rank}.pt")
    dist.destroy_process_group()


@pytest.mark.slow
@pytest.mark.integration
def test_two_gloo_ranks_on_the_device_path_hold_their_own_scenes(corpus, tmp_path):
    """torchrun-style ranks with --data device (2 processes, gloo, CPU): each rank loads only its own scenes (the
    shares disjoint, together the split), the samples counted over both ranks are every sample of the split once
    an epoch, and the two ranks end with one model."""
    import yaml

    from lfmbench.datasets.loading import make_dataset

    cfg_path = tmp_path / "tiny.yaml"  # the whole split: 3 scenes, 2 for rank 0 and 1 for rank 1
    cfg_path.write_text(yaml.safe_dump({**TINY, "train": {**TINY["train"], "split": "all"}}))
    torch.multiprocessing.start_processes(_device_rank, args=(2, _free_port(), corpus, cfg_path, tmp_path),
                                          nprocs=2, start_method="spawn")
    r0, r1 = (torch.load(tmp_path / f"dev{r}.pt") for r in (0, 1))
    ds = make_dataset(corpus, "all", seed=0, crop=8, samples_per_scene=4, frames=3)
    assert r0["held"] and r1["held"] and set(r0["held"][0]).isdisjoint(r1["held"][0])
    assert sorted(r0["held"][0] + r1["held"][0]) == sorted(ds.scene_ids)
    sps = ds.samples_per_scene
    for r in (r0, r1):
        assert {ds.scene_ids[i // sps] for _e, idx in r["seen"] for i in idx} <= set(r["held"][0])
    assert len(r0["weights"]) == len(r1["weights"])  # the same steps on both ranks
    for ep in (0, 1):
        counted = sorted(i for r in (r0, r1) for (e, idx), w in zip(r["seen"], r["weights"]) if e == ep and w > 0
                         for i in idx)
        assert counted == list(range(len(ds)))
    for k in r0["w"]:
        assert torch.equal(r0["w"][k], r1["w"][k])  # one model
