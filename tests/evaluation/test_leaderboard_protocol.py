"""lfmbench.evaluation.protocol_run: a second U-Net scored on the same samples as ``unet`` (``--unet-also``), the
LED score by scene-file field (``weather``) and the paired comparison of the two networks."""
from __future__ import annotations

import json
import os
import sys

import pytest

from lfmbench.registry import Registry
from tests.data.evaluation.data import make_led_corpus, write_result


@pytest.fixture(scope="module")
def lp():
    from lfmbench.evaluation import protocol_run

    return protocol_run


def test_extra_names_are_checked(tmp_path):
    from lfmbench.baselines.unet import parse_named_checkpoints

    ck = tmp_path / "u.pt"
    ck.write_bytes(b"x")
    assert parse_named_checkpoints([f"unet_v1trained={ck}"], {"unet": None}, "--unet-also") == \
        {"unet_v1trained": str(ck)}
    for bad in (f"unet={ck}", f"Bad-Name={ck}", str(ck), "unet_b=" + str(tmp_path / "missing.pt")):
        with pytest.raises(ValueError, match="--unet-also"):
            parse_named_checkpoints([bad], {"unet": None}, "--unet-also")
    with pytest.raises(ValueError, match="^--unet 'a=.*new snake_case"):
        parse_named_checkpoints([f"a={ck}", f"a={ck}"], {}, "--unet")


def test_field_tables_and_paired_difference(lp, tmp_path):
    from lfmbench.evaluation.leaderboard import load_runs

    ref = [0.9, 0.8, 0.7, 0.6]
    other = [0.8, 0.8, 0.5, 0.3]                                  # differences -0.1, 0, -0.2, -0.3
    paths = [write_result(tmp_path / "unet.json", ref, method="unet"),
             write_result(tmp_path / "u1.json", other, method="u1")]
    fields = {f"scene{i:05d}": {"weather": w} for i, w in enumerate(("dry", "wet", "dry", "wet"))}
    text = lp.scene_field_tables(load_runs(paths), fields, ["u1"])
    rows = {ln.split("|")[1].strip(): ln for ln in text.splitlines() if ln.startswith("| `")}
    assert rows["`unet`"].split("|")[3].strip().startswith("0.800 ")        # dry: mean(0.9, 0.7)
    assert rows["`u1`"].split("|")[4].strip().startswith("0.550 ")          # wet: mean(0.8, 0.3)
    diffs = {ln.split("|")[1].strip(): ln.split("|")[2].strip() for ln in text.splitlines()
             if ln.startswith("| all") or ln.startswith("| weather")}
    assert diffs["all"].startswith("-0.150 ")
    assert diffs["weather = dry"].startswith("-0.150 ") and diffs["weather = wet"].startswith("-0.150 ")


def test_a_second_copy_of_the_same_network_scores_the_same(lp, tmp_path, monkeypatch):
    """The extra network sees the very samples ``unet`` sees: the same weights give every scene the same score
    (paired difference 0 exactly), and the weather of each scene file is found."""
    import torch

    from lfmbench import baselines
    from lfmbench.baselines import unet as U
    from lfmbench.corpus import Corpus

    corpus = make_led_corpus(tmp_path / "corpus", n_scenes=4)
    c = Corpus(corpus)
    test_ids = json.loads((corpus / "splits.json").read_text())["test"]
    assert test_ids
    for i, sid in enumerate(test_ids):                               # give the test scenes a weather
        p = corpus / "scenes" / sid / "scene.json"
        p.write_text(json.dumps(dict(c.scene(sid), weather=("dry", "wet")[i % 2])))
    torch.manual_seed(0)
    cfg = U.config_from_dict({"model": {"base_channels": 2, "depth": 1}})
    ck = U.save_checkpoint(U.build_for_sensor(cfg), tmp_path / "u.pt", cfg)
    monkeypatch.setattr(sys, "argv", ["lp", "--corpus", str(corpus), "--checkpoint", str(ck), "--unet-also",
                                      f"unet_copy={ck}", "--runs", str(tmp_path / "runs"), "--samples-per-scene", "1"])
    monkeypatch.setenv(U.CHECKPOINT_ENV, str(ck))
    monkeypatch.setenv("LFMBENCH_UNET_COPY_CHECKPOINT", "")  # restored afterwards
    # two methods instead of every registered one (time); the script registers the copy in this registry only
    few = Registry("baseline")
    for m in ("lpd_only", "unet"):
        few.register(m, baselines.REGISTRY[m])
    monkeypatch.setattr(baselines, "REGISTRY", few)
    lp.main()
    assert "unet_copy" in baselines.REGISTRY and os.environ["LFMBENCH_UNET_COPY_CHECKPOINT"] == str(ck)
    a, b = (json.loads((tmp_path / "runs" / f"{m}.json").read_text()) for m in ("unet", "unet_copy"))
    sa = {r["scene_id"]: r["metrics"]["led_score"] for r in a["scenes"]}
    assert sa and sa == {r["scene_id"]: r["metrics"]["led_score"] for r in b["scenes"]}
    text = (tmp_path / "runs" / "scene_fields.md").read_text()
    assert "by scene `weather`" in text and "| all | +0.000 [" in text
    assert "`unet_copy`" in (tmp_path / "runs" / "leaderboard.md").read_text()
    # --only-unets: the networks alone (a second training seed scored on draws the rules have been scored on)
    monkeypatch.setenv("LFMBENCH_UNET_COPY2_CHECKPOINT", "")  # restored afterwards
    monkeypatch.setattr(sys, "argv", ["lp", "--corpus", str(corpus), "--checkpoint", str(ck), "--unet-also",
                                      f"unet_copy2={ck}", "--runs", str(tmp_path / "only"), "--samples-per-scene",
                                      "1", "--only-unets"])
    lp.main()
    made = sorted(p.name for p in (tmp_path / "only").glob("*.json"))
    assert "unet.json" in made and "unet_copy2.json" in made and "lpd_only.json" not in made
    c = json.loads((tmp_path / "only" / "unet.json").read_text())
    assert {r["scene_id"]: r["metrics"]["led_score"] for r in c["scenes"]} == sa  # the same frozen draws
