"""Captures from a corpus resident on the training device (issue 28, first part): the projected layers of a
split's scenes are loaded onto the device once, and every batch is cut, composed and simulated there.

The per-sample DataLoader path builds each sample's pieces in CPU workers (4 MiB of crops and gathered rates per
3-frame 256 x 256 sample) and copies them to the device. Here (:class:`DeviceBatches`):

1. :class:`ResidentScenes` holds, per scene, the static rates (Fs, 2, H, W), the flickering groups stored without
   bins, the per-light entries of every frame (2, K, N) (:class:`lfmbench.datasets.pieces._SceneEntries`), the
   full-frame ``light_index`` and ``depth``, all on the device (float32), within a stated memory budget: a split that
   does not fit raises :class:`ResidentMemoryError` before anything is copied.
2. Per sample, the host makes only the draws (``LFMCaptureDataset.draws``: functions of (seed, epoch, index)) and
   the small tables of :func:`lfmbench.datasets.pieces.capture_pieces` (slots, entry positions); the crops and the
   gathers of the rates run on the device, from the resident layers, by the same function and rules.
3. The batch is composed and simulated on the device by :func:`lfmbench.datasets.batched.simulate_batch` with
   counter-based noise (``noise_streams="counter"``: each sample's noise from its noise seed alone, no generator
   object per sample; :mod:`lfmbench.sensor.counter_noise`), the numbers the per-sample path gives with
   ``LFMCaptureDataset(..., noise_streams="counter")``.

Memory: a scene holds 4 bytes x (2 + 2) x Fs x H x W of static rates, light index (int16) and depth, plus 8 bytes x K
x (pixels inside its lamps' boxes) per frame; :meth:`ResidentScenes.estimate` gives the bytes of a split before
anything is loaded to the device (docs/datasets.md, "Corpus on the device": scenes per GB at 640x360 and 1920x1080).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Iterator

import torch

from lfmbench.datasets.batched import collate_pieces, pieces_to, simulate_batch
from lfmbench.datasets.pieces import _SceneEntries, capture_pieces
from lfmbench.vocabulary import PHOTODIODES

__all__ = ["ResidentMemoryError", "ResidentScene", "ResidentScenes", "DeviceBatches", "epoch_order",
           "DEFAULT_BUDGET_FRACTION"]

#: Share of the device's free memory a resident split may take by default (the rest: the batch, the network).
DEFAULT_BUDGET_FRACTION = 0.5


class ResidentMemoryError(ValueError):
    """A split's layers do not fit the memory budget of the device (raised before anything is copied)."""


def epoch_order(n: int, seed: int, epoch: int) -> torch.Tensor:
    """The order of an epoch's ``n`` samples: a permutation that depends only on ``(seed, epoch)`` (the one
    :class:`lfmbench.train.EpochSampler` uses)."""
    g = torch.Generator().manual_seed(int(seed) * 1_000_003 + int(epoch))
    return torch.randperm(int(n), generator=g)


@dataclass
class ResidentScene:
    """One scene's layers on a device (float32 rates in e-/s; ``light_index`` int16/int32; ``depth`` m)."""

    static: torch.Tensor           # (Fs, 2, H, W)
    group_static: dict             # group -> pd -> (Fs, H, W)
    entries: list                  # per frame: (2, Kscene, N) rates of the pixel entries
    light_index: torch.Tensor | None
    depth: torch.Tensor | None

    def nbytes(self) -> int:
        ts = [self.static, self.light_index, self.depth, *self.entries,
              *(t for g in self.group_static.values() for t in g.values())]
        return sum(int(t.numel()) * t.element_size() for t in ts if t is not None)


class ResidentScenes:
    """The projected layers of the scenes of ``ds`` (an :class:`~lfmbench.datasets.LFMCaptureDataset`) on ``device``.

    Args:
        ds: the dataset (its sensor, frames, groups and optics define the layers).
        device: torch device.
        budget_bytes: the most the layers may take (default: :data:`DEFAULT_BUDGET_FRACTION` of the device's free
            memory on CUDA; no limit on the CPU).

    Raises:
        ResidentMemoryError: the layers of the split need more than ``budget_bytes`` (the message gives both, the
            bytes per scene and how many scenes would fit); nothing has been copied to the device then.
    """

    def __init__(self, ds, device: torch.device | str, budget_bytes: int | None = None) -> None:
        self.device = torch.device(device)
        self.ds = ds
        want = set(ds.outputs)
        sids = list(dict.fromkeys(ds.scene_ids))
        sizes = {sid: self.estimate_scene(ds, sid) for sid in sids}
        need = sum(sizes.values())
        if budget_bytes is None and self.device.type == "cuda":
            free, _total = torch.cuda.mem_get_info(self.device)
            budget_bytes = int(DEFAULT_BUDGET_FRACTION * free)
        if budget_bytes is not None and need > budget_bytes:
            per = need / max(len(sids), 1)
            raise ResidentMemoryError(
                f"split {ds.split!r} of {ds.root}: its {len(sids)} scenes need {need / 2**30:.2f} GiB on {self.device} "
                f"({per / 2**20:.0f} MiB per scene), the budget is {budget_bytes / 2**30:.2f} GiB (about "
                f"{int(budget_bytes // per)} scenes): pass budget_bytes, use fewer scenes (a smaller split or "
                f"max_scenes), or train from the DataLoader path (data='loader')")
        self.bytes = 0
        self._scenes: dict[str, ResidentScene] = {}
        for sid in sids:
            view = ds.scene(sid)
            layers = view.layers
            dev = self.device
            ent = view.cached("pieces_entries", _SceneEntries)
            sc = ResidentScene(
                static=view.static_rates().to(dev),
                group_static={g: {pd: r[pd].to(dev) for pd in PHOTODIODES} for g, r in layers.group_static.items()},
                entries=[torch.from_numpy(fe.vals).to(dev) for fe in ent.frames],
                light_index=view.light_index().to(dev) if "light_index" in want else None,
                depth=layers.aux["depth.Z"].to(dev) if "depth" in want else None)
            self._scenes[sid] = sc
            self.bytes += sc.nbytes()

    @staticmethod
    def estimate_scene(ds, scene_id: str) -> int:
        """Bytes one scene's resident layers take (from its projected layers on the host)."""
        view = ds.scene(scene_id)
        layers = view.layers
        want = set(ds.outputs)
        fs, _two, H, W = (int(n) for n in view.static_rates().shape)
        n = 4 * 2 * fs * H * W
        n += sum(4 * int(r[pd].numel()) for r in layers.group_static.values() for pd in PHOTODIODES)
        n += sum(int(fe.vals.nbytes) for fe in view.cached("pieces_entries", _SceneEntries).frames)
        if "light_index" in want:
            n += int(view.light_index().numel()) * view.light_index().element_size()
        if "depth" in want:
            n += 4 * fs * H * W
        return n

    def scene(self, scene_id: str) -> ResidentScene:
        """The resident layers of ``scene_id`` (``KeyError`` naming it when it is not resident)."""
        try:
            return self._scenes[scene_id]
        except KeyError:
            raise KeyError(f"scene {scene_id!r} is not resident on {self.device}") from None


class DeviceBatches:
    """Simulated training batches of ``ds`` cut from its layers resident on ``device`` (see module docstring).

    Args:
        ds: an :class:`~lfmbench.datasets.LFMCaptureDataset` (not ``pieces=True``; its draws, sensor and outputs).
        batch_size: samples per batch (the last batch of an epoch may be smaller unless ``drop_last``).
        device: torch device of the layers, the simulation and the yielded tensors.
        seed: the order of an epoch's samples is :func:`epoch_order` ``(len(ds), seed, epoch)``.
        budget_bytes: see :class:`ResidentScenes`.
        drop_last: drop an epoch's last incomplete batch.

    Iterating yields the per-sample path's sample dicts with a leading B (on ``device``; ``meta`` collated on the
    CPU), noise from counter-based streams. ``set_epoch(e)`` selects the draws and the order of epoch ``e``.
    """

    def __init__(self, ds, batch_size: int, device: torch.device | str, seed: int = 0,
                 budget_bytes: int | None = None, drop_last: bool = False) -> None:
        if isinstance(batch_size, bool) or not isinstance(batch_size, int) or batch_size < 1:
            raise ValueError(f"batch_size must be an integer >= 1, got {batch_size!r}")
        if getattr(ds, "pieces", False):
            raise ValueError("ds: DeviceBatches builds the pieces itself; make the dataset without pieces=True")
        self.ds = ds
        self.batch_size = batch_size
        self.device = torch.device(device)
        self.seed = int(seed)
        self.drop_last = bool(drop_last)
        self.epoch = 0
        self.resident = ResidentScenes(ds, self.device, budget_bytes)

    def set_epoch(self, epoch: int) -> None:
        self.ds.set_epoch(epoch)
        self.epoch = int(epoch)

    def __len__(self) -> int:
        n = len(self.ds)
        return n // self.batch_size if self.drop_last else -(-n // self.batch_size)

    def batch(self, indices) -> dict:
        """The simulated batch of the dataset's samples ``indices`` (drawn for the current epoch)."""
        pieces = [capture_pieces(self.ds, sid, pl, pg, crop, ns, int(i), start, resident=self.resident)
                  for i in indices for sid, pl, pg, crop, ns, start in (self.ds.draws(int(i)),)]
        batch = pieces_to(collate_pieces(pieces), self.device)
        return simulate_batch(batch, self.ds.preset, noise_streams="counter")

    def __iter__(self) -> Iterator[dict]:
        order = epoch_order(len(self.ds), self.seed, self.epoch).tolist()
        for b in range(len(self)):
            yield self.batch(order[b * self.batch_size:(b + 1) * self.batch_size])
