"""A tiny corpus for the evaluation tests: bright flickering LEDs over a dim background, with a time of day and an
ego speed per scene (so the leaderboard's breakdown by condition has something to split).

Scene i gets ``TIMES[i % 3]`` and ``SPEEDS_MPS[i % len(SPEEDS_MPS)]``; its two LEDs (group ``otherlights``, PWM
drawn by the dataset) are ``led_gain`` times brighter than the background, the case where a method that only
passes the short exposure through extinguishes lights. Radiance in W sr^-1 m^-2 nm^-1.
"""
from __future__ import annotations

from lfmbench import corpus as C
from tests.data.corpus.data import H, W, fake_frames, fake_meta, fake_scene, scale_frames

TIMES = ("day", "dusk", "night")
SPEEDS_MPS = (0.0, 10.0, 20.0, 40.0)


def make_led_corpus(root, n_scenes: int = 6, frames: int = 3, bins: int = 4, scale: float = 1e-3,
                    led_gain: float = 20.0, seed: int = 0):
    """Write the corpus to ``root`` (train/val/test splits from ``write_splits(0)``) and return ``root``."""
    w = C.CorpusWriter(root)
    for i in range(n_scenes):
        sid = f"scene{i:05d}"
        meta = fake_meta(sid, width=W, height=H, frames=frames, bins=bins, n_lights=2)
        meta["camera"]["speed_mps"] = SPEEDS_MPS[i % len(SPEEDS_MPS)]
        fr = scale_frames(fake_frames(meta, seed=seed + i), scale, scale * led_gain)
        w.write_scene(sid, dict(fake_scene(sid), time_of_day=TIMES[i % len(TIMES)]), meta, fr)
    w.write_splits(0)
    return root
