"""lfmbench.check: the shared field checks and the one scene-id rule."""
from __future__ import annotations

import copy
import math
import re

import numpy as np
import pytest
import torch

from lfmbench import check
from lfmbench import corpus as C
from tests.data.corpus.data import fake_meta

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


@pytest.mark.parametrize("value,kw,msg", [
    (True, {}, "must be a number, got True"),
    ("1", {}, "must be a number"),
    (math.nan, {}, "must be finite"),
    (math.inf, {}, "must be finite"),
    (0.0, {"lo": 0.0, "lo_open": True}, "must be > 0.0, got 0.0"),
    (-1, {"lo": 0.0}, "must be >= 0.0, got -1"),
    (2.0, {"lo": 0.0, "hi": 1.0}, r"must be in \[0.0, 1.0\], got 2.0"),
    (1.0, {"lo": 0.0, "hi": 1.0, "hi_open": True}, r"must be in \[0.0, 1.0\), got 1.0"),
    (2.5, {"integer": True}, "must be an integer, got 2.5"),
])
def test_check_number_names_field_and_source(value, kw, msg):
    with pytest.raises(ValueError, match=rf"^cfg\.yaml: field 'a\.b' {msg}"):
        check.check_number(value, "a.b", "cfg.yaml", **kw)


def test_check_number_passes_and_converts():
    assert check.check_number(np.float32(0.5), "x", lo=0, hi=1) == 0.5
    assert check.check_number(3.0, "x", integer=True) == 3 and isinstance(check.check_number(3.0, "x", integer=True), int)
    assert check.check_number(math.inf, "x", allow_inf=True) == math.inf
    with pytest.raises(ValueError, match="finite"):
        check.check_number(-math.inf, "x", allow_inf=True)
    with pytest.raises(ValueError, match=r"^field 'x' must be a number"):  # no source: field only
        check.check_number(None, "x")


def test_get_number_missing_and_default():
    assert check.get_number({"a": 2}, "a", "f.json", lo=0) == 2.0
    assert check.get_number({}, "a", "f.json", default=7) == 7
    with pytest.raises(ValueError, match=r"^f\.json: field 'timing\.a' is missing"):
        check.get_number({}, "a", "f.json", "timing.")


def test_check_integer_vector_choice():
    assert check.check_integer(3, "n", "f") == 3
    for bad in (True, 3.0, -1):
        with pytest.raises(ValueError, match="f: field 'n' must be an integer"):
            check.check_integer(bad, "n", "f")
    assert check.check_vector([1, 2, 3], "p", "f") == [1.0, 2.0, 3.0]
    with pytest.raises(ValueError, match=r"field 'p\[1\]' must be <= 1"):
        check.check_vector([0, 5, 0], "p", "f", hi=1)
    with pytest.raises(ValueError, match="list of 2 numbers"):
        check.check_vector([0, 5, 0], "p", "f", n=2)
    with pytest.raises(ValueError, match=r"f: field 'sync' must be one of \['light', 'group'\], got 'x'"):
        check.check_choice("x", "sync", ("light", "group"), "f")


def test_check_keys():
    d = {"a": 1, "b": 2}
    assert check.check_keys(d, "sec", "f", required=["a"], optional=["b"]) is d
    assert check.check_keys(d, "sec", "f", required=["a"], optional=None) is d  # others allowed
    with pytest.raises(ValueError, match=r"^f: unknown fields 'sec\.b', 'sec\.c'"):
        check.check_keys({"a": 1, "b": 2, "c": 3}, "sec", "f", required=["a"])
    with pytest.raises(ValueError, match=r"^f: field 'sec\.z' is missing"):
        check.check_keys(d, "sec", "f", required=["z"], optional=None)
    with pytest.raises(ValueError, match=r"^f: field 'sec' must be an object"):
        check.check_keys([1], "sec", "f")


def test_check_array_numpy_torch_and_bounds():
    check.check_array("duty", torch.tensor([0.1, 0.9]), lo=0.0, hi=1.0)
    with pytest.raises(ValueError, match="period must be > 0.0; got 0.0"):
        check.check_array("period", np.array([1.0, 0.0]), lo=0.0, lo_open=True)
    with pytest.raises(ValueError, match="phase must be finite"):
        check.check_array("phase", torch.tensor([math.nan]))
    with pytest.raises(ValueError, match="real number"):
        check.check_array("phase", np.array(["a"]))


def test_users_of_the_module_name_field_and_file(tmp_path):
    """The former copies (sensor, optics, PWM, corpus meta, scene files) now raise through lfmbench.check."""
    from lfmbench.datasets.pwm import load_pwm_config
    from lfmbench.sensor.optics import OpticsConfig

    with pytest.raises(ValueError, match=r"^pwm: field 'sync' must be one of"):
        load_pwm_config({"sync": "all"})
    with pytest.raises(ValueError, match=r"^pwm: unknown field 'dutty'"):
        load_pwm_config({"dutty": {"dist": "constant", "value": 0.2}})
    with pytest.raises(ValueError, match=r"^lens\.yaml: field 'optics\.psf_oversample' must be an integer"):
        OpticsConfig.from_mapping({"psf_oversample": 0}, "lens.yaml")
    with pytest.raises(ValueError, match=r"^lens\.yaml: unknown field 'optics\.zoom'"):
        OpticsConfig.from_mapping({"zoom": 2}, "lens.yaml")
    meta = fake_meta()
    meta["timing"]["short_exposure_s"] = -1.0
    with pytest.raises(ValueError, match=r"^m\.json: field 'timing\.short_exposure_s' must be > 0"):
        C.validate_meta(meta, "m.json")


def test_torch_device_names_the_argument():
    import torch

    from lfmbench.check import torch_device

    assert torch_device("cpu") == torch.device("cpu")
    with pytest.raises(ValueError, match="--device must be a torch device.*'banana'"):
        torch_device("banana")
    if not torch.cuda.is_available():
        with pytest.raises(ValueError, match="--gpu cuda: CUDA is not available"):
            torch_device("cuda", "--gpu")


# ------------------------------------------------------------------------------------------------ tensors
@pytest.mark.parametrize("spec, shape, ok", [
    ("B F 1 H W", (2, 3, 1, 4, 5), True), ("B F 1 H W", (2, 3, 2, 4, 5), False), ("B F 1 H W", (3, 1, 4, 5), False),
    ("* 1 H W", (1, 4, 5), True), ("* 1 H W", (7, 2, 1, 4, 5), True), ("* 1 H W", (4, 5), False),
    ("* 1 H W", (3, 4, 5), False), ("N * 3 H W", (2, 3, 4, 4), True), ("N * 3 H W", (2, 9, 9, 3, 4, 4), True),
    ("N * 3 H W", (3, 4, 4), False), ("*", (), True),
])
def test_shape_spec_against_enumerated_shapes(spec, shape, ok):
    x = torch.zeros(shape)
    if ok:
        check.check_tensor(x, "x", spec)
    else:
        want = f"x must have shape ({spec.replace(' ', ', ')}), got {tuple(shape)}"
        with pytest.raises(ValueError, match="^" + re.escape(want) + "$"):
            check.check_tensor(x, "x", spec)


def test_tensor_checks_name_the_argument_and_keep_the_error_type():
    with pytest.raises(TypeError, match="^raw must be a torch.Tensor, got list$"):
        check.check_tensor([1.0], "raw", "* 1 H W")
    with pytest.raises(ValueError, match=r"^raw must be a Bayer mosaic of shape \(\*, 1, H, W\), got \(2, 3\)$"):
        check.check_tensor(torch.zeros(2, 3), "raw", "* 1 H W", what="a Bayer mosaic")
    with pytest.raises(ValueError, match="^raw must be a floating-point tensor, got torch.int64$"):
        check.check_tensor(torch.zeros(1, 2, 2, dtype=torch.long), "raw", "* 1 H W", floating=True)
    with pytest.raises(ValueError, match=r"^pred must have at least 5 dims, got shape \(2, 2\)$"):
        check.check_tensor(torch.zeros(2, 2), "pred", min_dim=5)
    bad = torch.tensor([[[0.0, math.nan]]])
    with pytest.raises(ValueError, match="^gt must be finite; got NaN or inf$"):
        check.check_tensor(bad, "gt", finite=True)
    with check.trusted_values():  # value checks off for the package's own tensors; shape checks stay
        check.check_tensor(bad, "gt", "1 1 2", finite=True)
        with pytest.raises(ValueError, match="gt must have shape"):
            check.check_tensor(bad, "gt", "1 2", finite=True)


def test_same_shape_and_batch_checks():
    with pytest.raises(ValueError, match=r"^pred and gt must have the same shape, got pred \(1, 2\) and gt \(1, 3\)$"):
        check.check_same_shape(torch.zeros(1, 2), torch.zeros(1, 3), "pred", "gt")
    with pytest.raises(TypeError, match="^gt must be a torch.Tensor"):
        check.check_same_shape(torch.zeros(1), 0.0, "pred", "gt")
    check.check_same_shape(torch.zeros(2), torch.zeros(2, dtype=torch.float64), "pred", "gt")  # dtype not asked
    with pytest.raises(ValueError, match=r"^pred and gt must have the same dtype, got pred torch.float32 and gt "
                                         r"torch.float64$"):
        check.check_same_shape(torch.zeros(2), torch.zeros(2, dtype=torch.float64), "pred", "gt", dtype=True)
    with pytest.raises(ValueError, match="^batch: missing 'info'; pass it$"):
        check.check_batch_keys({"static": 1}, ("static", "info"), hint="pass it")
    b = {"static": torch.zeros(1), "t0": torch.zeros(1, device="meta"), "n": 3}
    with pytest.raises(ValueError, match=r"^batch\['t0'\] is on meta but batch\['static'\] is on cpu; move it$"):
        check.check_same_device(b, "static", hint="move it")
    assert check.check_same_device({"static": torch.zeros(1), "n": 3}, "static") == torch.device("cpu")
