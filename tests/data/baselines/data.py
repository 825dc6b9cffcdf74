"""Tiny U-Net checkpoints for the tests that score or show several trained networks by name."""
from __future__ import annotations

from pathlib import Path


def random_unets(root, seeds=(0, 1)) -> list[Path]:
    """One checkpoint per seed in ``root`` (``u<seed>.pt``): an untrained U-Net of 2 channels and depth 1 whose
    weights are all drawn from N(0, 0.1), so that networks of different seeds give different outputs (an untrained
    head is zero, which would make every network's output the same)."""
    import torch

    from lfmbench.baselines import unet as U

    cfg = U.config_from_dict({"model": {"base_channels": 2, "depth": 1}})
    paths = []
    for seed in seeds:
        torch.manual_seed(seed)
        model = U.build_for_sensor(cfg)
        with torch.no_grad():
            for p in model.parameters():
                p.normal_(0.0, 0.1)
        paths.append(U.save_checkpoint(model, Path(root) / f"u{seed}.pt", cfg))
    return paths
