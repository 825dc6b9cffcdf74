"""The recipes of docs/guide/extending.md, executed: a sensor preset from a folder of one's own, a metric, a
rule-based and a learned baseline registered through the public registries, and the rule a new scene element
(a vehicle kind) must follow. Every toy entry is removed again after its test."""
from __future__ import annotations

import sys

import pytest
import torch
import yaml

from lfmbench import baselines, sensor
from lfmbench.baselines import REGISTRY, get_method, methods_for, register_learned
from lfmbench.metrics import REGISTRY as METRICS, MetricSpec, ScoreOptions, register_metric, score_batch
from lfmbench.registry import Registry
from tests.data.metrics.data import make_batch

#: Linear metrics only (the display-referred columns run the ISP: slower, not what these tests are about).
LINEAR = ScoreOptions(isp=None)


# ------------------------------------------------------------------------------------------ a sensor preset
def test_a_preset_from_a_yaml_file_of_ones_own(tmp_path, corpus):
    """Recipe: copy a shipped preset, change it, load it by path; the dataset simulates with it."""
    data = yaml.safe_load((sensor.PRESET_DIR / "single.yaml").read_text())
    data.update(name="single_quiet", description="single exposure with 0.5 e- read noise")
    data["captures"]["main"]["read_noise_e"] = 0.5
    path = tmp_path / "single_quiet.yaml"
    path.write_text(yaml.safe_dump(data))
    p = sensor.load_preset(path)
    assert (p.name, p.architecture, p.captures["main"].read_noise_e) == ("single_quiet", "single", 0.5)
    assert "single_quiet" not in sensor.available_presets()  # a file elsewhere is loaded by path, not listed

    from lfmbench.datasets import LFMCaptureDataset

    ds = LFMCaptureDataset(corpus, split="all", sensor=path, noise=False, crop=8)
    s = ds[0]
    assert ds.sensor_name == "single_quiet" and s["main_e"].shape == s["gt"].shape == (3, 1, 8, 8)
    with pytest.raises(ValueError, match="captures.main.read_noise_e"):
        data["captures"]["main"]["read_noise_e"] = -1.0
        path.write_text(yaml.safe_dump(data))
        sensor.load_preset(path)


# ------------------------------------------------------------------------------------------------ a metric
def test_a_metric_is_one_register_metric_call(request):
    """Recipe: a MetricSpec with its function, registered; every score_batch then reports it."""
    def mean_ratio(pred, batch, options):
        """Mean output over mean ground truth per sample, (B,) (1 for a perfect fusion)."""
        return pred.flatten(1).mean(1) / batch["gt"].flatten(1).mean(1)

    register_metric(MetricSpec("mean_ratio", "1.0", "ratio of means (docs/guide/extending.md)", "1", True, "hdr",
                               "mean ratio", fn=mean_ratio, valid=(0.0, float("inf"))))
    request.addfinalizer(lambda: METRICS.unregister("mean_ratio"))
    b = make_batch(b=2, seed=3)
    got = score_batch(b["gt"] * 0.5, b, LINEAR)
    assert [r["mean_ratio"] for r in got] == pytest.approx([0.5, 0.5])


# --------------------------------------------------------------------------------------------- baselines
def test_a_rule_baseline_is_one_decorator(request):
    """Recipe: a function of the batch, registered by name; get_method, methods_for and scoring find it."""
    @REGISTRY.register("lcg_only")
    def lcg_only(batch: dict) -> torch.Tensor:
        """The LPD low-conversion-gain capture alone, (B, F, 1, H, W) e-."""
        return batch["lpd_lcg_e"]

    request.addfinalizer(lambda: REGISTRY.unregister("lcg_only"))
    assert get_method("lcg_only") is lcg_only and "lcg_only" in methods_for("split_pixel")
    assert "lcg_only" not in methods_for("lofic")  # a split-pixel rule; other plans list their merges
    b = make_batch(seed=1)
    assert score_batch(lcg_only(b), b, LINEAR)[0]["psnr_mu"] > 0


def test_a_learned_baseline_is_one_register_learned_call(tmp_path, monkeypatch, request):
    """Recipe: a module defining the method (and, for ``lfmbench train``, ``TRAINING``), registered by name and
    module; the module is imported on first use."""
    (tmp_path / "toy_learned_fusion.py").write_text(
        "def toy_learned(batch):\n    return 2.0 * batch['lpd_lcg_e']\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    register_learned("toy_learned", "toy_learned_fusion")

    def forget():
        for reg in (baselines.REGISTRY, baselines.LEARNED):
            reg.unregister("toy_learned")
        sys.modules.pop("toy_learned_fusion", None)

    request.addfinalizer(forget)
    assert "toy_learned_fusion" not in sys.modules  # lazy: registering imports nothing
    b = make_batch(seed=2)
    assert torch.equal(get_method("toy_learned")(b), 2.0 * b["lpd_lcg_e"])
    assert baselines.LEARNED.get("toy_learned") == "toy_learned_fusion"
    assert "toy_learned" in methods_for("split_pixel")


# ------------------------------------------------------------------------------------------ a scene element
def test_every_vehicle_kind_has_one_template_and_one_name():
    """Recipe: a vehicle kind is a template of render_tools.scene_templates plus its name in
    lfmbench.vocabulary.VEHICLE_KINDS; the two lists must agree, and each template has what the generator reads."""
    from lfmbench.vocabulary import VEHICLE_KINDS
    from render_tools.scene_templates import VEHICLE_TEMPLATES

    assert set(VEHICLE_TEMPLATES) == set(VEHICLE_KINDS)
    for kind, t in VEHICLE_TEMPLATES.items():
        assert {"length", "boxes", "wheels", "tail", "head", "cargo", "lights_by_day"} <= set(t), kind
        assert t["length"] > 0 and all(len(b) == 3 for b in t["boxes"]), kind


def test_a_registry_of_ones_own_follows_the_same_rule():
    """The one pattern behind every registry above."""
    widgets: Registry = Registry("widget")
    widgets.register("a", 1)
    with pytest.raises(ValueError, match="^unknown widget 'b'; valid: a$"):
        widgets.get("b")
