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


def write_result(path, scores=(0.5, 0.6), method="m", metric="led_score", extra=None):
    """A minimal complete result file (``lfmbench-eval`` version 2) with one sample record per score, the
    scenes ``scene00000``, ``scene00001``, ...; ``extra`` updates the top level. Returns ``path``."""
    import json
    from pathlib import Path

    recs = [{"scene_id": f"scene{i:05d}", "index": i, "status": "ok", "metrics": {metric: s}, "conditions": {}}
            for i, s in enumerate(scores)]
    doc = {"format": "lfmbench-eval", "version": 2, "method": {"spec": method}, "status": "complete",
           "runtime": {"device": "cpu", "ms_per_megapixel": 1.0}, "aggregate": {}, "scenes": recs,
           "dataset": {"split": "test", "samples_per_scene": 1}, "seeds": {"dataset": 0},
           "corpus": {"scenes_sha256": "0" * 64, "format_version": 2}}
    doc.update(extra or {})
    Path(path).write_text(json.dumps(doc) if not isinstance(scores, str) else scores)
    return Path(path)
