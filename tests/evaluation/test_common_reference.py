"""Cross-sensor columns against one truth (``ScoreOptions(reference="common")``): the full-image and ghost columns of
two sensors are computed against the same ``gt_common``, the LED columns against each sensor's own ``gt``; the
estimate's map to the common units; results record the reference and a cross-sensor ranking refuses results
scored against their own sensor's gt."""
from __future__ import annotations

import json

import pytest
import torch

from lfmbench.metrics import ScoreOptions, flicker, hdr, regions, score_batch
from lfmbench.metrics.scoring import to_common
from tests.data.evaluation.data import make_led_corpus


def test_to_common_undoes_a_per_phase_gain():
    """An estimate equal to its own gt maps onto gt_common exactly when the two truths differ by one gain per 2x2
    CFA phase (and per sample); the estimate's error is scaled by the same gains, not fitted away."""
    g = torch.Generator().manual_seed(0)
    gt = torch.rand(2, 3, 1, 6, 8, generator=g, dtype=torch.float64) + 0.1
    gains = torch.tensor([[[0.5, 2.0], [3.0, 0.25]], [[1.5, 1.0], [0.75, 4.0]]], dtype=torch.float64)
    full = gains.repeat(1, 3, 4)[:, None, None]                                # (2, 1, 1, 6, 8)
    gc = gt * full
    torch.testing.assert_close(to_common(gt, gt, gc), gc, rtol=1e-12, atol=0)
    err = torch.rand(gt.shape, generator=g, dtype=torch.float64)
    torch.testing.assert_close(to_common(gt + err, gt, gc), gc + err * full, rtol=1e-12, atol=0)


@pytest.fixture(scope="module")
def two_sensors(tmp_path_factory):
    from lfmbench.datasets import LFMCaptureDataset
    from lfmbench.datasets.loading import collate_samples

    root = make_led_corpus(tmp_path_factory.mktemp("common") / "c", n_scenes=1, frames=2)
    kw = dict(split="all", frames=2, cache_dir=False, noise=False, optics=False, seed=3,
              outputs=("raw", "input_referred", "saturated", "gt", "light_index", "gt_common"))
    return {n: collate_samples([LFMCaptureDataset(root, sensor=n, **kw)[0]]) for n in ("staggered", "single")}


def test_two_sensors_cross_columns_use_the_same_reference(two_sensors, monkeypatch):
    """Every cross-sensor column (full image: PSNR-mu; ghost: the outside-LED block) receives the same reference
    tensor for both sensors, ``gt_common``; the LED block receives each sensor's own ``gt``, which differ."""
    seen: dict[str, list] = {"psnr_mu": [], "outside": [], "flicker": []}
    real = (hdr.psnr_mu, regions.outside_led_metrics, flicker.region_flicker_metrics)

    def spy_psnr(p, g, *a, **k):
        seen["psnr_mu"].append(g.clone())
        return real[0](p, g, *a, **k)

    def spy_outside(p, g, *a, **k):
        seen["outside"].append(g.clone())
        return real[1](p, g, *a, **k)

    def spy_flicker(p, g, *a, **k):
        seen["flicker"].append(g.clone())
        return real[2](p, g, *a, **k)
    monkeypatch.setattr(hdr, "psnr_mu", spy_psnr)
    monkeypatch.setattr(regions, "outside_led_metrics", spy_outside)
    monkeypatch.setattr(flicker, "region_flicker_metrics", spy_flicker)
    for name, b in two_sensors.items():
        score_batch(b["gt"] * 0.9, b, ScoreOptions(isp=None, sensor=name, reference="common"))
    a, s = two_sensors["staggered"], two_sensors["single"]
    assert not torch.allclose(a["gt"], s["gt"], rtol=0.05)                   # the sensors' own truths differ
    for key in ("psnr_mu", "outside"):
        assert len(seen[key]) == 2
        torch.testing.assert_close(seen[key][0], seen[key][1], rtol=0, atol=0)
        torch.testing.assert_close(seen[key][0], a["gt_common"].to(seen[key][0].dtype))
    torch.testing.assert_close(seen["flicker"][0], a["gt"])
    torch.testing.assert_close(seen["flicker"][1], s["gt"])


def test_reference_common_scores_against_gt_common_and_keeps_led_columns(two_sensors):
    """A perfect estimate of the common truth (gt_common in the sensor's units) scores perfectly on the cross
    columns and, against its own gt, exactly as with the own reference on the LED columns; own-reference scoring
    of the same estimate is not perfect (the two truths differ by more than a gain per phase)."""
    b = two_sensors["staggered"]
    gt, gc = b["gt"], b["gt_common"].to(b["gt"].dtype)
    inv = to_common(torch.ones_like(gt), gc, gt)        # per-phase gain sum(gt) / sum(gt_common)
    pred = gc * inv                                      # gt_common in the sensor's units: to_common(pred) == gc
    com = score_batch(pred, b, ScoreOptions(isp=None, sensor="staggered", reference="common"))[0]
    own = score_batch(pred, b, ScoreOptions(isp=None, sensor="staggered"))[0]
    assert com["psnr_mu"] > 100 and com["ghost_mae_mu"] < 1e-6                 # float64 round-off only
    assert own["psnr_mu"] < com["psnr_mu"] - 20
    for k in ("led_rel_err", "dropout_rate", "fmi_abs_err", "psnr_mu_led"):
        assert com[k] == own[k] or (com[k] != com[k] and own[k] != own[k]), k
    with pytest.raises(ValueError, match="gt_common"):
        score_batch(pred, {k: v for k, v in b.items() if k != "gt_common"}, ScoreOptions(isp=None, reference="common"))
    with pytest.raises(ValueError, match="reference must be one of"):
        score_batch(pred, b, ScoreOptions(isp=None, reference="theirs"))


def test_results_record_the_reference_and_cross_sensor_ranking_needs_it(tmp_path):
    """``benchmark_sensors`` scores against gt_common (``options.reference``, result version 3); a cross-sensor
    leaderboard of results scored against their own gt is refused, naming the files; a single-sensor result keeps
    its options as before (no ``reference`` key)."""
    from lfmbench.evaluation import leaderboard as lb
    from lfmbench.evaluation.benchmark import benchmark, benchmark_sensors

    corpus = make_led_corpus(tmp_path / "corpus", n_scenes=1)
    kw = dict(split="all", perceptual=False, repeats=1, isp=None, progress=False)
    benchmark_sensors(corpus, {"single": ["exposure_select"], "staggered": ["exposure_select"]}, tmp_path / "x", **kw)
    res = [json.loads(p.read_text()) for p in (tmp_path / "x" / "single" / "exposure_select.json",
                                              tmp_path / "x" / "staggered" / "exposure_select.json")]
    assert all(r["options"]["reference"] == "common" and r["version"] == 3 for r in res)
    own = dict(res[1], options={k: v for k, v in res[1]["options"].items() if k != "reference"})
    (tmp_path / "own").mkdir()
    (tmp_path / "own" / "exposure_select.json").write_text(json.dumps(own))   # as scored against its own gt
    runs = lb.load_runs([tmp_path / "x" / "single" / "exposure_select.json", tmp_path / "own" / "exposure_select.json"])
    with pytest.raises(lb.IncomparableRunsError, match="not the common reference: exposure_select.json"):
        lb.check_comparable(runs, cross_sensor=True)
    with pytest.raises(ValueError, match="simulate='host'"):
        benchmark(corpus, ["exposure_select"], tmp_path / "d", sensor="staggered", simulate="device",
                  reference="common", **kw)
