"""A small learned fusion network (about 3.6 k parameters) trained through a DataLoader, with checkpoints.

The network does not regress radiance directly: per pixel and frame it predicts softmax weights over three
physically meaningful candidates in the GT units (input-referred e-), so it stays in range and trains on CPU in
minutes:

1. ``L``: the exposure-corrected saturated fusion (sharp, flickers),
2. ``S``: the SPD, ``spd_e`` (flicker-free up to the long exposure, blurred, noisier),
3. ``T``: the frame mean of ``L`` (temporal average of the LED level, ghosts on motion).

Features (per frame, per pixel): log1p of L, S and T over :data:`FEATURE_SCALE_E`, and the three saturation
flags. Loss: L1 between the mu-law tone-mapped output and GT, both normalised by the GT peak
(:func:`lfmbench.metrics.hdr.normalize_hdr`, :func:`~lfmbench.metrics.hdr.mu_law`; Kalantari & Ramamoorthi 2017).

Defines :class:`LearnedFusion` (``nn.Module``, input the batch dict), :func:`train`, :func:`save_checkpoint`,
:func:`load_checkpoint` and the registered method :func:`learned`, which reads the checkpoint at
``$LFMBENCH_LEARNED_CHECKPOINT`` or :data:`DEFAULT_CHECKPOINT` and raises :class:`CheckpointNotFoundError`
with the training command when there is none.

Training script: ``python -m lfmbench.baselines.learned --corpus DIR --epochs 3 --checkpoint runs/learned_fusion.pt``.
"""
from __future__ import annotations

import argparse
import time
from collections.abc import Callable, Iterable
from pathlib import Path

import torch

from lfmbench.baselines.checkpoint import CheckpointedModel
from lfmbench.fileio import atomic_torch_save
import torch.nn as nn

from lfmbench.baselines.classic import saturated_fusion, _captures
from lfmbench.metrics.hdr import mu_law, normalize_hdr

#: Where :func:`learned` looks for weights unless ``$LFMBENCH_LEARNED_CHECKPOINT`` is set.
DEFAULT_CHECKPOINT = Path("runs") / "learned_fusion.pt"
CHECKPOINT_ENV = "LFMBENCH_LEARNED_CHECKPOINT"
#: Scale (input-referred e-) inside the log1p feature transform.
FEATURE_SCALE_E = 100.0
#: Checkpoint format version (bump when the architecture changes).
FORMAT_VERSION = 1


class CheckpointNotFoundError(FileNotFoundError):
    """No trained weights for the learned baseline."""


class LearnedFusion(nn.Module):
    """Per-pixel softmax blend of (L, S, T) predicted by a 4-layer 3x3 conv net.

    Args:
        width: hidden channels (12 -> 3.6 k parameters).

    Input: batch dict with ``lpd_hcg_e``, ``lpd_lcg_e``, ``spd_e`` (B, F, 1, H, W) e- and ``saturated``
    (B, F, 3, H, W). Output: (B, F, 1, H, W) e-.
    """

    def __init__(self, width: int = 12):
        super().__init__()
        self.width = width
        self.net = nn.Sequential(
            nn.Conv2d(6, width, 3, padding=1), nn.ReLU(),
            nn.Conv2d(width, width, 3, padding=2, dilation=2), nn.ReLU(),
            nn.Conv2d(width, width, 3, padding=1), nn.ReLU(),
            nn.Conv2d(width, 3, 3, padding=1),
        )
        with torch.no_grad():  # start as the plain saturated fusion: weight on L
            self.net[-1].bias.copy_(torch.tensor([2.0, 0.0, 0.0]))

    @staticmethod
    def candidates(batch: dict) -> tuple[torch.Tensor, torch.Tensor]:
        """Candidates (B, F, 3, H, W) e- = (L, S, T) and saturation flags (B, F, 3, H, W) float."""
        hcg, lcg, spd, sat = _captures(batch)
        lo = saturated_fusion(hcg, lcg, spd, sat)
        t = lo.mean(dim=1, keepdim=True).expand_as(lo)
        return torch.cat([lo, spd, t], dim=2), sat.to(lo.dtype)

    def forward(self, batch: dict) -> torch.Tensor:
        cand, sat = self.candidates(batch)
        b, f, _, h, w = cand.shape
        feats = torch.cat([torch.log1p(cand.clamp_min(0.0) / FEATURE_SCALE_E), sat], dim=2)
        logits = self.net(feats.reshape(b * f, 6, h, w).float()).reshape(b, f, 3, h, w)
        wts = torch.softmax(logits, dim=2).to(cand.dtype)
        return (wts * cand).sum(dim=2, keepdim=True)


def fusion_loss(pred: torch.Tensor, gt: torch.Tensor) -> torch.Tensor:
    """Mean L1 of mu-law tone-mapped, GT-peak-normalised images (scalar, dimensionless)."""
    p, g = normalize_hdr(pred, gt, "max")
    return (mu_law(p) - mu_law(g)).abs().mean()


def save_checkpoint(model: LearnedFusion, path: str | Path, extra: dict | None = None) -> Path:
    """Write ``{'format_version', 'width', 'state_dict', ...extra}`` atomically (temp file + ``os.replace``)."""
    return atomic_torch_save({"format_version": FORMAT_VERSION, "width": model.width,
                              "state_dict": model.state_dict(), **(extra or {})}, path)


def load_checkpoint(path: str | Path, map_location: str | torch.device = "cpu") -> LearnedFusion:
    """Build a :class:`LearnedFusion` from a checkpoint; clear errors for a missing or foreign file."""
    path = Path(path)
    if not path.is_file():
        raise CheckpointNotFoundError(
            f"no learned-fusion checkpoint at {path}; train one with `python -m lfmbench.baselines.learned "
            f"--corpus DIR --checkpoint {path}` (or set ${CHECKPOINT_ENV})")
    ck = torch.load(path, map_location=map_location, weights_only=True)
    if not isinstance(ck, dict) or ck.get("format_version") != FORMAT_VERSION:
        raise ValueError(f"checkpoint {path} is not a lfmbench learned-fusion checkpoint of format {FORMAT_VERSION}")
    model = LearnedFusion(int(ck["width"]))
    model.load_state_dict(ck["state_dict"])
    return model.eval()


def train(loader: Iterable[dict], checkpoint: str | Path | None = None, epochs: int = 1, lr: float = 3e-3,
          width: int = 12, max_steps: int | None = None, seed: int = 0, device: str | torch.device = "cpu",
          model: LearnedFusion | None = None, progress: bool = False,
          log: Callable[[str], None] | None = None) -> tuple[LearnedFusion, list[float]]:
    """Train :class:`LearnedFusion` with Adam on batches from ``loader`` (e.g. a DataLoader of the dataset).

    Args:
        loader: iterable of batch dicts (re-iterated once per epoch).
        checkpoint: where to save the weights after each epoch (atomic), or None.
        epochs, lr, width, max_steps: optimisation settings (max_steps caps the total number of steps).
        seed: seeds the weight initialisation (``torch.manual_seed``).
        device: training device.
        model: continue training this model instead of a fresh one.
        progress: show a tqdm bar.
        log: optional callback for one line per epoch.

    Returns:
        (trained model in eval mode, per-step losses).
    """
    torch.manual_seed(seed)
    model = (model or LearnedFusion(width)).to(device).train()
    opt = torch.optim.Adam(model.parameters(), lr=lr)
    losses: list[float] = []
    step = 0
    for ep in range(epochs):
        t0 = time.perf_counter()
        dataset = getattr(loader, "dataset", None)
        if hasattr(dataset, "set_epoch"):
            dataset.set_epoch(ep)  # fresh PWM draws, crops and noise every epoch
        it = loader
        if progress:
            from tqdm import tqdm

            it = tqdm(loader, desc=f"epoch {ep + 1}/{epochs}", leave=False)
        for batch in it:
            batch = {k: (v.to(device) if isinstance(v, torch.Tensor) else v) for k, v in batch.items()}
            loss = fusion_loss(model(batch), batch["gt"])
            opt.zero_grad()
            loss.backward()
            opt.step()
            losses.append(float(loss.detach()))
            step += 1
            if max_steps is not None and step >= max_steps:
                break
        if log:
            n = max(1, min(len(losses), 20))
            log(f"epoch {ep + 1}: loss {sum(losses[-n:]) / n:.4f} ({time.perf_counter() - t0:.1f} s, {step} steps)")
        if checkpoint is not None:
            save_checkpoint(model, checkpoint, {"epochs": ep + 1, "steps": step, "lr": lr, "seed": seed,
                                                "losses": losses})
        if max_steps is not None and step >= max_steps:
            break
    return model.eval(), losses


#: Where the weights are (``$LFMBENCH_LEARNED_CHECKPOINT`` or :data:`DEFAULT_CHECKPOINT`), loaded once per file version.
WEIGHTS = CheckpointedModel(CHECKPOINT_ENV, DEFAULT_CHECKPOINT, load_checkpoint)
checkpoint_path = WEIGHTS.path
_model = WEIGHTS.model


def learned(batch: dict) -> torch.Tensor:
    """Registered method: :class:`LearnedFusion` with the weights at :func:`checkpoint_path`.

    Returns (B, F, 1, H, W) e-. Raises :class:`CheckpointNotFoundError` if no checkpoint exists.
    """
    return WEIGHTS.run(batch)


#: Lets the evaluation count parameters and MACs of the module behind :func:`learned`.
learned.torch_module = _model  # type: ignore[attr-defined]


def main(argv: list[str] | None = None) -> None:
    """Training script: ``python -m lfmbench.baselines.learned --corpus DIR [--epochs N] [--checkpoint PATH]``."""
    ap = argparse.ArgumentParser(description="Train the lfmbench learned fusion baseline on a corpus.")
    ap.add_argument("--corpus", required=True, help="corpus root directory")
    ap.add_argument("--split", default="train")
    ap.add_argument("--checkpoint", default=str(checkpoint_path()))
    ap.add_argument("--epochs", type=int, default=3)
    ap.add_argument("--batch-size", type=int, default=4)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--lr", type=float, default=3e-3)
    ap.add_argument("--max-steps", type=int, default=None)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--crop", type=int, default=None, help="square random crop in px (default: full frames)")
    ap.add_argument("--samples-per-scene", type=int, default=16,
                    help="samples (PWM draws, crops) per scene per epoch")
    a = ap.parse_args(argv)
    from torch.utils.data import DataLoader

    from lfmbench.datasets import make_dataset, collate_samples

    ds = make_dataset(a.corpus, a.split, seed=a.seed, crop=a.crop, samples_per_scene=a.samples_per_scene)
    loader = DataLoader(ds, batch_size=a.batch_size, shuffle=True, num_workers=a.workers,
                        collate_fn=collate_samples, generator=torch.Generator().manual_seed(a.seed))
    model, losses = train(loader, a.checkpoint, epochs=a.epochs, lr=a.lr, max_steps=a.max_steps, seed=a.seed,
                          progress=True, log=print)
    print(f"saved {a.checkpoint} ({sum(p.numel() for p in model.parameters())} parameters, final loss "
          f"{losses[-1] if losses else float('nan'):.4f})")


if __name__ == "__main__":  # pragma: no cover
    main()
