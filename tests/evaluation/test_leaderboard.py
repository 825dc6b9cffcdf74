"""The LED-first leaderboard: ranking on a generated corpus, statistics in the JSON and Markdown, corpus identity
refusals, and the one-entry metric registry."""
from __future__ import annotations

import json
import math

import pytest
import typer
from typer.testing import CliRunner

from lfmbench import evaluation as ev
from lfmbench.cli.evaluate import register as register_evaluate
from lfmbench.evaluation.benchmark import benchmark as run_benchmark
from lfmbench.evaluation import leaderboard as lb
from lfmbench.evaluation import stats
from lfmbench.metrics import REGISTRY, MetricSpec, ScoreOptions, register_metric, score_batch
from tests.data.evaluation.data import TIMES, make_led_corpus
from tests.data.metrics.data import make_batch

METHODS = ("lpd_only", "flicker_aware", "spd_only")


@pytest.fixture(scope="module")
def bench(tmp_path_factory):
    """Three baselines scored on a 6-scene corpus of bright flickering LEDs (split 'all')."""
    d = tmp_path_factory.mktemp("lb")
    corpus = make_led_corpus(d / "corpus", n_scenes=6)
    rows = run_benchmark(corpus, METHODS, d / "runs", split="all", perceptual=False, repeats=1, progress=False)
    return d, corpus, rows


def _app():
    app = typer.Typer()
    register_evaluate(app)
    return app


def test_lpd_only_does_not_rank_first_by_the_led_score(bench):
    d, _, rows = bench
    by_led = [r["method"] for r in rows]
    runs = ev.load_runs([d / "runs" / f"{m}.json" for m in METHODS])
    by_psnr = [r["method"] for r in ev.leaderboard_rows(runs, "psnr_mu")]
    assert by_psnr[0] == "lpd_only"  # full-image PSNR-mu favours the sharp short exposure ...
    assert by_led[0] != "lpd_only"  # ... which extinguishes lights: the LED score does not rank it first
    lpd, fa = (next(r for r in rows if r["method"] == m) for m in ("lpd_only", "flicker_aware"))
    assert lpd["dropout_rate"] > fa["dropout_rate"] and lpd["led_score"] < fa["led_score"]
    assert by_led.index("flicker_aware") < by_led.index("lpd_only")


def test_result_json_has_identity_per_scene_ci_and_breakdown(bench):
    d, corpus, _ = bench
    res = json.loads((d / "runs" / "lpd_only.json").read_text())
    assert res["version"] == 3 and "reference" not in res["options"]   # own gt: options as in version 2
    import hashlib

    assert res["corpus"]["manifest_sha256"] == hashlib.sha256((corpus / "manifest.json").read_bytes()).hexdigest()
    assert res["corpus"]["format_version"] == json.loads((corpus / "manifest.json").read_text())["version"]
    assert res["versions"]["metrics"]["led_score"] == REGISTRY["led_score"].version
    assert res["statistics"]["n_resamples"] == stats.N_RESAMPLES and res["statistics"]["seed"] == stats.SEED
    per = {s["scene_id"]: s for s in res["per_scene"]}
    assert len(per) == 6 and per["scene00002"]["conditions"]["time_of_day"] == TIMES[2]
    vals = [s["metrics"]["led_score"] for s in res["per_scene"]]
    agg = res["aggregate"]
    assert agg["led_score"] == pytest.approx(sum(vals) / 6)
    lo, hi = agg["ci"]["led_score"]
    assert lo <= agg["led_score"] <= hi and (lo, hi) == pytest.approx(stats.bootstrap_ci(vals))
    tod = res["breakdown"]["by"]["time_of_day"]
    assert set(tod) == set(TIMES) and all(tod[t]["n"] == 2 for t in TIMES)
    night = [per[s]["metrics"]["led_score"] for s in per if per[s]["conditions"]["time_of_day"] == "night"]
    assert tod["night"]["value"] == pytest.approx(sum(night) / 2)
    assert set(res["breakdown"]["by"]["ego_speed_mps"]) == {"[0, 5)", "[5, 15)", "[15, 30)", "[30, inf)"}


def test_leaderboard_json_and_markdown_hold_the_paired_tests(bench):
    d, _, rows = bench
    js = json.loads((d / "runs" / "leaderboard.json").read_text())
    assert js["sort_by"] == "led_score" and [r["method"] for r in js["rows"]] == [r["method"] for r in rows]
    best = {s["scene_id"]: s["metrics"]["led_score"] for s in js["per_scene"][rows[0]["method"]]}
    ps = []
    for r in js["rows"][1:]:
        mine = {s["scene_id"]: s["metrics"]["led_score"] for s in js["per_scene"][r["method"]]}
        diffs = [mine[k] - best[k] for k in best]
        assert r["vs_best"]["n"] == 6 and r["vs_best"]["mean_diff"] == pytest.approx(sum(diffs) / 6)
        assert r["vs_best"]["p"] == pytest.approx(stats.wilcoxon_p(diffs))
        ps.append(r["vs_best"]["p"])
    assert [r["vs_best"]["p_holm"] for r in js["rows"][1:]] == pytest.approx(stats.holm(ps))
    assert js["rows"][0]["vs_best"] is None and js["corpus"]["manifest_sha256"]
    md = (d / "runs" / "leaderboard.md").read_text()
    assert "LED score [95 % CI]" in md and "p / p Holm" in md and "| time_of_day | day | dusk | night |" in md
    assert "Wilcoxon" in md and f"{stats.N_RESAMPLES} resamples" in md


def test_leaderboard_refuses_other_corpus_and_metric_versions(bench, tmp_path):
    d, _, _ = bench
    other = make_led_corpus(tmp_path / "other", n_scenes=2, seed=5)
    out = tmp_path / "o.json"
    r = CliRunner().invoke(_app(), ["evaluate", "--method", "lpd_only", "--corpus", str(other), "--split", "all",
                                    "--output", str(out), "--repeats", "1", "--no-perceptual"])
    assert r.exit_code == 0, r.output
    args = ["--markdown", str(tmp_path / "l.md"), "--plot", str(tmp_path / "l.png"), "--json", str(tmp_path / "l.json")]
    r = CliRunner().invoke(_app(), ["leaderboard", str(d / "runs" / "flicker_aware.json"), str(out), *args])
    assert r.exit_code == 2 and "corpus scenes sha256 differs: scenes " in r.output
    assert "flicker_aware.json" in r.output and "o.json" in r.output and not (tmp_path / "l.md").exists()
    r = CliRunner().invoke(_app(), ["leaderboard", str(d / "runs" / "flicker_aware.json"), str(out), *args,
                                    "--include-incomplete"])
    assert r.exit_code == 2  # --include-incomplete is about status, not about mixing corpora
    old = json.loads((d / "runs" / "spd_only.json").read_text())
    old["versions"]["metrics"]["led_rel_err"] = "0.9"
    (tmp_path / "spd_old.json").write_text(json.dumps(old))
    r = CliRunner().invoke(_app(), ["leaderboard", str(d / "runs" / "lpd_only.json"), str(tmp_path / "spd_old.json"),
                                    *args])
    assert r.exit_code == 2 and "metric versions differ" in r.output
    assert "led_rel_err: 1.0 in lpd_only.json; 0.9 in spd_old.json" in r.output
    r = CliRunner().invoke(_app(), ["leaderboard", str(d / "runs" / "lpd_only.json"),
                                    str(d / "runs" / "spd_only.json"), *args])
    assert r.exit_code == 0, r.output
    assert (tmp_path / "l.json").is_file() and "ranked by led_score" in r.output
    (tmp_path / "bins.yaml").write_text("speed: {edges: [3, 1]}\n")
    r = CliRunner().invoke(_app(), ["leaderboard", str(d / "runs" / "lpd_only.json"), *args,
                                    "--conditions", str(tmp_path / "bins.yaml")])
    assert r.exit_code == 2 and "bins.yaml: speed.edges" in r.output


def test_adding_a_metric_is_one_registry_entry(request, tmp_path):
    def bright(pred, batch, o):
        """Mean output / mean GT, (B,)."""
        return pred.flatten(1).mean(1) / batch["gt"].flatten(1).mean(1)

    register_metric(MetricSpec("brightness", "1.0", "test", "1", True, "hdr", "BRIGHT", fn=bright, show="console"))
    request.addfinalizer(lambda: REGISTRY.unregister("brightness"))
    b = make_batch(seed=1)
    assert score_batch(b["gt"] * 2, b)[0]["brightness"] == pytest.approx(2.0)
    for m, scale in (("a", 1.0), ("b", 0.5)):
        ev.evaluate(lambda x, s=scale: x["gt"] * s, [make_batch(seed=i) for i in range(3)], method_spec=m,
                    output=tmp_path / f"{m}.json", repeats=1, progress=False)
    res = json.loads((tmp_path / "b.json").read_text())
    assert res["aggregate"]["brightness"] == pytest.approx(0.5) and "brightness" in res["versions"]["metrics"]
    rows = ev.leaderboard_rows(ev.load_runs([tmp_path / "a.json", tmp_path / "b.json"]), "brightness")
    assert [r["method"] for r in rows] == ["a", "b"]
    assert "| BRIGHT |" in ev.leaderboard_markdown(rows) and "BRIGHT [95 % CI]" in ev.leaderboard_markdown(rows,
                                                                                                         "brightness")


def test_registry_is_consistent():
    from lfmbench.metrics import BLOCKS, PRIMARY
    from lfmbench.metrics.registry import _BLOCK_OF_GROUP

    assert PRIMARY in REGISTRY and REGISTRY[PRIMARY].higher_is_better
    for s in REGISTRY.values():
        assert (s.fn is not None) + (s.derive is not None) <= 1
        if s.fn is None and s.derive is None:
            assert _BLOCK_OF_GROUP[s.group] in BLOCKS, s.name
    b = make_batch(seed=0, noise=True)
    got = score_batch(b["lpd_lcg_e"], b)[0]
    assert {k for k, s in REGISTRY.items() if s.group != "perceptual"} <= set(got)


def test_led_score_against_its_formula():
    b = make_batch(seed=2, noise=True)
    s = score_batch(b["lpd_lcg_e"], b)[0]
    want = ((1 - s["dropout_rate"]) * (1 - s["fmi_abs_err"]) * (1 - s["led_rel_err"])) ** (1 / 3)
    assert s["led_score"] == pytest.approx(want)
    assert score_batch(b["gt"].clone(), b)[0]["led_score"] == pytest.approx(1.0)  # exact output: every factor 1
    off = b["gt"].clone()
    off[b["light_index"] >= 0] = 0.0  # every light extinguished: dropout 1 -> score 0
    assert score_batch(off, b)[0]["led_score"] == 0.0


def test_perceptual_block_runs_once_per_batch(monkeypatch):
    from lfmbench.metrics import hdr

    try:
        hdr.load_pycvvdp()
    except hdr.CvvdpUnavailableError as exc:
        pytest.skip(f"cvvdp not importable here: {exc}")
    calls = {"block": 0, "lum": 0}
    real_block, real_lum = hdr.perceptual_metrics, hdr.to_display_luminance

    def block(*a, **k):
        calls["block"] += 1
        return real_block(*a, **k)

    def lum(*a, **k):
        calls["lum"] += 1
        return real_lum(*a, **k)

    monkeypatch.setattr(hdr, "perceptual_metrics", block)
    monkeypatch.setattr(hdr, "to_display_luminance", lum)
    b = make_batch(b=2, seed=3, noise=True)
    pred = b["lpd_lcg_e"]
    s = score_batch(pred, b, ScoreOptions(perceptual=True))
    assert calls == {"block": 1, "lum": 4}  # one block call; pred and gt converted once per sample
    monkeypatch.setattr(hdr, "to_display_luminance", real_lum)
    assert [x["pu21_psnr"] for x in s] == pytest.approx(hdr.pu21_psnr(pred, b["gt"]).tolist(), rel=1e-5)
    assert [x["cvvdp_jod"] for x in s] == pytest.approx(hdr.cvvdp_jod(pred, b["gt"]).tolist(), rel=1e-5)


def test_pareto_front_by_hand():
    rows = [{"method": m, "status": "complete", "led_score": a, "psnr_mu_outside": o}
            for m, a, o in (("x", 0.9, 20.0), ("y", 0.8, 30.0), ("z", 0.7, 25.0), ("w", float("nan"), 40.0))]
    lb._pareto(rows, lb.PARETO_AXES)
    assert [r["pareto"] for r in rows] == [True, True, False, None]  # z is dominated by y
    assert math.isnan(rows[3]["led_score"])


def test_leaderboard_glob_over_its_own_output_directory_runs_twice(bench, tmp_path):
    """`lfmbench leaderboard runs/*.json` as the README writes it: the runs directory already holds the
    leaderboard.json an earlier call (or benchmark()) wrote; it is left out with a note, not refused."""
    d, _, rows = bench
    files = sorted((d / "runs").glob("*.json"))
    assert any(p.name == "leaderboard.json" for p in files)
    out = tmp_path / "lb"
    args = ["leaderboard", *map(str, files), "--markdown", str(out / "lb.md"), "--plot", str(out / "lb.png"),
            "--json", str(out / "lb.json")]
    r = CliRunner().invoke(_app(), args)
    assert r.exit_code == 0, r.output
    assert "left out 1 leaderboard file(s)" in r.output
    assert [x["method"] for x in json.loads((out / "lb.json").read_text())["rows"]] == [x["method"] for x in rows]


def test_corpus_identity_follows_the_scored_scenes_not_the_whole_manifest(tmp_path):
    """Two corpora with the same two scenes (byte-identical files) but a third scene in one of them: the
    manifests differ, the identity of the scored scenes does not (a protocol corpus scored after ``--split test``
    stays comparable once its training scenes are added); other scenes or an edited file change it."""
    from lfmbench.evaluation.provenance import corpus_identity
    from tests.data.corpus.data import make_corpus

    a, b = make_corpus(tmp_path / "a", n_scenes=2), make_corpus(tmp_path / "b", n_scenes=3)
    ids = ["scene00000", "scene00001"]
    ia, ib = corpus_identity(a, ids), corpus_identity(b, ids)
    assert ia["manifest_sha256"] != ib["manifest_sha256"]
    assert ia["scenes_sha256"] == ib["scenes_sha256"] is not None
    assert lb.identity({"corpus": ia})["corpus scenes sha256"] == lb.identity({"corpus": ib})["corpus scenes sha256"]
    assert corpus_identity(b, ["scene00000", "scene00002"])["scenes_sha256"] != ib["scenes_sha256"]
    man = json.loads((b / "manifest.json").read_text())
    key = next(k for k in man["files"] if k.startswith("scenes/scene00001/"))
    man["files"][key] = "0" * 64
    (b / "manifest.json").write_text(json.dumps(man))
    assert corpus_identity(b, ids)["scenes_sha256"] != ia["scenes_sha256"]
    with pytest.raises(ValueError, match=r"no files listed for scene\(s\) \['nope'\]"):
        corpus_identity(a, ["nope"])
    assert corpus_identity(a)["scenes_sha256"] is None


def test_forked_statistics_and_sweep_json_equal_one_process(bench, tmp_path, monkeypatch):
    """A leaderboard of PARALLEL_STATS_ROWS or more rows computes its rows' bootstrap statistics in a forked pool
    of 2 processes, and a sweep's JSON (more rows than STATS_ROWS) is written by a forked process while this one
    writes the Markdown and the plot: the rows and the JSON bytes equal those of one process, and an error of the
    JSON writer reaches the caller naming the file."""
    import json

    from lfmbench.evaluation import benchmark as BM
    from lfmbench.evaluation import leaderboard as L
    from lfmbench.evaluation.leaderboard import rank
    from lfmbench.evaluation.results import jsonable

    d, _, _ = bench
    src = [json.loads((d / "runs" / f"{m}.json").read_text()) for m in METHODS]
    paths = []
    for i in range(3):                       # 9 results: three copies of each, each its own method name
        for r in src:
            r = json.loads(json.dumps(r))
            r["method"]["spec"] = f"{r['method']['spec']}-{i}"
            p = tmp_path / f"{r['method']['spec']}.json"
            p.write_text(json.dumps(r))
            paths.append(p)
    assert len(paths) >= L.PARALLEL_STATS_ROWS
    forked = L.leaderboard_rows(L.load_runs(paths))
    monkeypatch.setattr(rank, "PARALLEL_STATS_ROWS", 10 ** 9)
    one = L.leaderboard_rows(L.load_runs(paths))
    assert json.dumps(jsonable(forked)) == json.dumps(jsonable(one)) and all(r["ci"] for r in one)
    runs = L.load_runs(paths)
    monkeypatch.setattr(rank, "STATS_ROWS", 4)  # 9 rows: a sweep's JSON
    BM.write_leaderboard(one, runs, None, tmp_path / "a.md", tmp_path / "a.png", tmp_path / "a.json")
    monkeypatch.setattr(BM, "_forked", lambda fn: None)
    BM.write_leaderboard(one, runs, None, tmp_path / "b.md", tmp_path / "b.png", tmp_path / "b.json")
    assert (tmp_path / "a.json").read_bytes() == (tmp_path / "b.json").read_bytes()
    monkeypatch.undo()
    monkeypatch.setattr(rank, "STATS_ROWS", 4)
    (tmp_path / "file").write_text("a file, not a folder")
    with pytest.raises(Exception, match="file/c.json"):
        BM.write_leaderboard(one, runs, None, tmp_path / "c.md", tmp_path / "c.png", tmp_path / "file" / "c.json")
    assert (tmp_path / "file").read_text() == "a file, not a folder"
