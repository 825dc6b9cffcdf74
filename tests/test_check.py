"""lfmbench.check: the shared field checks and the one scene-id rule."""
from __future__ import annotations

import copy
import math

import numpy as np
import pytest
import torch

from lfmbench import check
from lfmbench import corpus as C
from tests.test_corpus_data import fake_meta

# (id, valid): the edge cases of the rule, each checked by every user of it
SCENE_IDS = [
    ("scene00000", True), ("1112201236", True), ("a", True), ("A.b-c_d", True), ("a.", True), ("x" * 255, True),
    ("a+b", False), ("", False), (".hidden", False), ("-a", False), ("_a", False), ("a/b", False),
    ("a\\b", False), ("a b", False), ("..", False), ("a\n", False), ("caf\u00e9", False), ("x" * 256, False),
    (7, False), (None, False),
]


@pytest.mark.parametrize("sid,ok", SCENE_IDS)
def test_one_scene_id_rule_for_corpus_and_scene_files(sid, ok):
    from render_tools import scene as S

    assert (check.scene_id_error(sid) is None) == ok
    sc = copy.deepcopy(S.empty_scene())
    sc["scene_id"] = sid
    meta = fake_meta()
    meta["scene_id"] = sid
    if ok:
        assert check.check_scene_id(sid) == sid
        C.check_scene_id(sid)
        S.validate_scene(sc)
        C.validate_meta(meta, "meta.json")
    else:
        with pytest.raises(ValueError, match="meta.json: field 'scene_id'"):
            C.validate_meta(meta, "meta.json")
        with pytest.raises(ValueError, match="field 'scene_id'"):
            check.check_scene_id(sid)
        with pytest.raises(ValueError, match="scene_id"):
            C.check_scene_id(sid)
        with pytest.raises(ValueError, match=r"scene\.scene_id"):
            S.validate_scene(sc)
