"""lfmbench.isp.pipeline: pipeline files (errors name the file and the field), shipped pipelines, every preset,
gradients."""
from __future__ import annotations

import pytest
import torch

from lfmbench.isp import ISP, compand, load_pipeline, pipeline_from_dict, srgb_encode, tonemap
from lfmbench.isp.pipeline import available_pipelines
from lfmbench.sensor import available_presets, mosaic


# -------------------------------------------------------------------------------------------------- pipelines
def _pipe(**override) -> dict:
    d = {"format": "lfmbench-isp", "name": "t", "steps": [
        {"op": "black_level", "level": 0}, {"op": "white_balance"}, {"op": "demosaic"}, {"op": "ccm"},
        {"op": "tonemap"}, {"op": "srgb_encode"}]}
    d.update(override)
    return d


@pytest.mark.parametrize("steps, match", [
    ([{"op": "frobnicate"}], r"t\.yaml: field 'steps\[0\]\.op' must be one of"),
    ([{"op": "demosaic"}, {"op": "white_balance"}], r"field 'steps\[1\]' works on the mosaic"),
    ([{"op": "tonemap"}, {"op": "demosaic"}], r"field 'steps\[0\]' works on the rgb"),
    ([{"op": "white_balance"}], r"field 'steps' has no demosaic"),
    ([{"op": "demosaic", "methd": "x"}], r"unknown field 'steps\[0\]\.methd'"),
    ([{"op": "demosaic", "method": "vng"}], r"field 'steps\[0\]\.method' must be one of"),
    ([{"op": "demosaic"}, {"op": "tonemap", "method": "durand2002", "key": 1}], r"unknown field 'steps\[1\]\.key'"),
    ([{"op": "demosaic"}, {"op": "tonemap", "white": "brightest"}], r"field 'steps\[1\]\.white'"),
    ([{"op": "compand", "knees": [[0, 0], [5, 9]]}, {"op": "demosaic"}], r"steps\[0\]\.knees\[1\]"),
    ([{"op": "demosaic"}, {"op": "ccm", "matrix": [[1, 0], [0, 1]]}], r"steps\[1\]\.matrix"),
    ([{"op": "demosaic", "clamp": "yes"}], r"steps\[0\]\.clamp' must be true or false"),
])
def test_pipeline_errors_name_file_and_field(steps, match):
    with pytest.raises(ValueError, match=match):
        pipeline_from_dict(_pipe(steps=steps), "t.yaml")


def test_pipeline_file_errors(tmp_path):
    with pytest.raises(ValueError, match="unknown pipeline"):
        load_pipeline("no_such_pipeline")
    bad = tmp_path / "bad.yaml"
    bad.write_text("format: lfmbench-isp\nname: x\nsteps: []\n")
    with pytest.raises(ValueError, match=r"bad\.yaml: field 'steps' must be a non-empty list"):
        load_pipeline(bad)
    with pytest.raises(ValueError, match="field 'format'"):
        pipeline_from_dict(_pipe(format="other"), "t.yaml")


def test_shipped_pipelines_load_and_hash():
    assert {"default", "local"} <= set(available_pipelines())
    p = load_pipeline("default")
    assert [s.op for s in p.stages] == ["black_level", "compand", "white_balance", "demosaic", "ccm", "tonemap",
                                       "srgb_encode"]
    assert len(p.sha256) == 64 and p.sha256 != load_pipeline("local").sha256
    assert load_pipeline("default").sha256 == p.sha256


@pytest.mark.parametrize("preset", available_presets())
@pytest.mark.parametrize("name", ["default", "local"])
def test_isp_runs_for_every_preset_and_maps_pairs_the_same_way(preset, name):
    isp = ISP(name, preset)
    gen = torch.Generator().manual_seed(2)
    gt = torch.rand(2, 3, 1, 20, 24, generator=gen) ** 3 * 5e4
    p, g = isp.pair(gt.clone(), gt)
    assert p.shape == (2, 3, 3, 20, 24) and torch.equal(p, g)
    assert float(g.min()) >= 0.0 and float(g.max()) <= 1.0
    assert torch.equal(isp(gt), g)  # forward without reference: the image is its own reference
    p2, g2 = isp.pair(gt * 4.0, gt)
    assert torch.equal(g2, g) and float(p2.mean()) > float(g.mean())
    one = isp(gt[0, 0])  # (1, H, W) works too
    assert one.shape == (3, 20, 24)


def test_isp_gradient_flows_to_the_estimate():
    isp = ISP("default", "ovt")
    gt = torch.rand(1, 2, 1, 16, 16, dtype=torch.float64) * 1e3 + 10
    pred = (gt * 1.3).requires_grad_(True)
    p, g = isp.pair(pred, gt)
    (p - g).pow(2).mean().backward()
    assert pred.grad is not None and torch.isfinite(pred.grad).all() and float(pred.grad.abs().sum()) > 0


def test_isp_black_level_preset_for_dn_input():
    pipe = _pipe(steps=[{"op": "black_level", "level": "preset"}, {"op": "demosaic"}])
    isp = ISP(pipeline_from_dict(pipe), "ovt")
    raw = torch.full((1, 1, 4, 4), 64.0 + 10.0)
    assert torch.allclose(isp(raw), torch.full((1, 3, 4, 4), 10.0))
