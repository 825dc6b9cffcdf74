"""Loading helpers shared by training and evaluation: a checked :class:`LFMCaptureDataset` and a collate function.

- :func:`make_dataset`: the dataset over a corpus split, with one-line errors for a missing corpus or an empty split.
- :func:`collate_samples`: batch sample dicts (tensors stacked, ``meta`` collated when its fields line up).

They live with the datasets (not with the evaluation) so that a baseline that trains on a corpus
(``lfmbench.baselines.learned``) does not import the evaluation stage above it.
"""
from __future__ import annotations

from pathlib import Path


class EmptyDataError(ValueError):
    """The data source holds no scene."""


def make_dataset(corpus: str | Path, split: str = "test", seed: int = 0, crop: int | None = None, **kwargs):
    """``lfmbench.datasets.LFMCaptureDataset(corpus, split=split, seed=seed, ...)``, with clear errors.

    Args:
        corpus: corpus root directory (holds ``manifest.json``).
        split: ``train``, ``val``, ``test`` or ``all``.
        seed: dataset seed (PWM draws, noise).
        crop: square crop in px, or None for the full frame.
        kwargs: passed on to :class:`~lfmbench.datasets.LFMCaptureDataset`.

    Raises:
        FileNotFoundError: ``corpus`` is not a directory.
        EmptyDataError: the split holds no scene.
    """
    root = Path(corpus)
    if not root.is_dir():
        raise FileNotFoundError(f"corpus directory {root} does not exist; render one with `lfmbench render --out DIR` "
                                "(or `lfmbench demo`)")
    from lfmbench.datasets.capture import LFMCaptureDataset

    if crop is not None:
        kwargs["crop"] = crop
    ds = LFMCaptureDataset(root, split=split, seed=seed, **kwargs)
    if len(ds) == 0:
        raise EmptyDataError(f"corpus {root}: split {split!r} holds no scenes")
    return ds


def collate_samples(samples: list[dict]) -> dict:
    """Collate sample dicts into a batch: tensors stacked (``default_collate``: (F, C, H, W) -> (B, F, C, H, W)),
    ``meta`` collated when its fields line up, else kept as a list of per-sample dicts."""
    from torch.utils.data import default_collate

    out = default_collate([{k: v for k, v in s.items() if k != "meta"} for s in samples])
    metas = [s.get("meta", {}) for s in samples]
    try:
        out["meta"] = default_collate(metas)
    except Exception:
        out["meta"] = metas
    return out
