"""The fake corpus data of ``tests/data/corpus/data.py`` has the documented shapes.

The generators moved to ``tests/data/corpus/data.py``; they are re-exported here for code that still imports
them from this module.
"""
from __future__ import annotations

from tests.data.corpus.data import BANDS, fake_frames, fake_meta, fake_scene  # noqa: F401 - re-exported

def test_fake_frames_match_meta():
    meta = fake_meta()
    frames = fake_frames(meta)
    assert len(frames) == meta["frames"]
    assert frames[0]["static"]["headlights"]["short"].shape == (3, 8, 12)
    lid, box, arr = frames[1]["lights"]["otherlights"][1]
    assert arr.shape == (3, 3, box[2] - box[0], box[3] - box[1])
