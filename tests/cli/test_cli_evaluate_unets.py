"""``lfmbench evaluate --unet NAME=CHECKPOINT``: several trained U-Nets scored in one command, each written as
``<runs-dir>/NAME.json`` with its own checkpoint SHA-256, scored as the ``unet`` method with those weights; bad
items refused naming ``--unet`` before anything is written; a changed checkpoint refuses to resume."""
from __future__ import annotations

import json

import pytest
import torch
from typer.testing import CliRunner

from lfmbench.evaluation.provenance import file_sha256

#: Options of every evaluation here: 2 scenes of one frame, one timed call, no perceptual metrics, no ISP.
TINY = ["--split", "all", "--frames", "1", "--no-perceptual", "--isp", "none", "--repeats", "1", "--warmup", "0",
        "--threads", "1"]
#: Environment variables the command sets for its networks (restored after each test).
ENVS = ("LFMBENCH_NET_A_CHECKPOINT", "LFMBENCH_NET_B_CHECKPOINT", "LFMBENCH_UNET_CHECKPOINT")


def _evaluate(args: list[str]):
    """``lfmbench evaluate ARGS`` (torch's thread count restored afterwards)."""
    from lfmbench.cli import app

    threads = torch.get_num_threads()
    try:
        return CliRunner().invoke(app, ["evaluate", *args, *TINY])
    finally:
        torch.set_num_threads(threads)


def _metrics(d: dict) -> list:
    """(scene id, metrics) of every sample record of a result."""
    return [(s["scene_id"], s["metrics"]) for s in d["scenes"]]


@pytest.fixture(scope="module")
def two_nets(tmp_path_factory):
    """A 2-scene corpus, two untrained U-Nets (2 channels, depth 1) with different random weights, and the result
    folder of one ``--unet net_b=B --unet net_a=A`` run."""
    from tests.data.baselines.data import random_unets
    from tests.data.corpus.data import make_corpus

    root = tmp_path_factory.mktemp("evaluate_unets")
    corpus = make_corpus(root / "c", n_scenes=2)
    a, b = random_unets(root)
    runs = root / "runs"
    with pytest.MonkeyPatch.context() as mp:
        for env in ENVS:
            mp.setenv(env, "")
        r = _evaluate(["--unet", f"net_b={b}", "--unet", f"net_a={a}", "--corpus", str(corpus),
                       "--runs-dir", str(runs)])
    assert r.exit_code == 0, r.output
    return corpus, a, b, runs, r.output


def test_two_networks_in_one_run_score_as_the_unet_with_their_weights(two_nets, tmp_path, monkeypatch):
    corpus, a, b, runs, output = two_nets
    assert sorted(p.name for p in runs.glob("*.json")) == ["net_a.json", "net_b.json"]
    assert output.index("net_b: 2/2 scenes ok") < output.index("net_a: 2/2 scenes ok")   # in the order given
    res = {n: json.loads((runs / f"{n}.json").read_text()) for n in ("net_a", "net_b")}
    for name, ck in (("net_a", a), ("net_b", b)):
        d = res[name]
        assert d["status"] == "complete" and d["method"]["spec"] == name
        assert d["method"]["checkpoint"]["file_sha256"] == file_sha256(ck), name      # its own weights recorded
        assert d["method"]["checkpoint"]["path"] == str(ck) and d["method"]["checkpoint"]["verified"] is True
    assert res["net_a"]["method"]["checkpoint"]["content_sha256"] != \
        res["net_b"]["method"]["checkpoint"]["content_sha256"]
    assert _metrics(res["net_a"]) != _metrics(res["net_b"])                      # different weights, other scores
    monkeypatch.setenv("LFMBENCH_UNET_CHECKPOINT", str(a))                        # the environment-variable route
    alone = tmp_path / "alone.json"
    r = _evaluate(["-m", "unet", "--corpus", str(corpus), "--output", str(alone)])
    assert r.exit_code == 0, r.output
    d = json.loads(alone.read_text())
    assert _metrics(d) == _metrics(res["net_a"])
    assert d["method"]["checkpoint"]["content_sha256"] == res["net_a"]["method"]["checkpoint"]["content_sha256"]
    from lfmbench.cli import app

    r = CliRunner().invoke(app, ["leaderboard", str(runs / "net_a.json"), str(runs / "net_b.json"),
                                 "--markdown", str(tmp_path / "lb.md"), "--plot", str(tmp_path / "lb.png"),
                                 "--json", str(tmp_path / "lb.json")])
    assert r.exit_code == 0, r.output
    rows = json.loads((tmp_path / "lb.json").read_text())["rows"]
    assert {row["method"]: row["checkpoint_sha256"] for row in rows} == {
        n: res[n]["method"]["checkpoint"]["content_sha256"] for n in ("net_a", "net_b")}


@pytest.mark.parametrize("args, why", [
    ("--unet net_a", "give NAME=CHECKPOINT"),                                  # no checkpoint
    ("--unet Net-A={a}", "give NAME=CHECKPOINT"),                              # not snake_case
    ("--unet unet={a}", "give NAME=CHECKPOINT"),                               # a registered method's name
    ("-m lpd_only --unet lpd_only={a}", "give NAME=CHECKPOINT"),               # ... here also a --method
    ("--unet net_a={a} --unet net_a={b}", "give NAME=CHECKPOINT"),             # the name of an earlier --unet
    ("--unet net_a={missing}", "no such file"),
    ("--unet net_a={notweights}", "cannot be read as weights"),                # a file that is no checkpoint
    ("-m my_mod:fn --unet my_mod_fn={a}", "give NAME=CHECKPOINT"),             # the --method's my_mod_fn.json
    ("", "give at least one --method METHOD or --unet NAME=CHECKPOINT"),       # neither option
])
def test_a_bad_network_is_refused_naming_the_option_and_nothing_is_written(two_nets, tmp_path, monkeypatch,
                                                                          args, why):
    corpus, a, b, *_ = two_nets
    for env in (*ENVS, "LFMBENCH_MY_MOD_FN_CHECKPOINT", "LFMBENCH_LPD_ONLY_CHECKPOINT"):
        monkeypatch.setenv(env, "")
    (tmp_path / "junk.pt").write_text("not weights")
    args = args.format(a=a, b=b, missing=tmp_path / "missing.pt", notweights=tmp_path / "junk.pt").split()
    runs = tmp_path / "runs"
    r = _evaluate([*args, "--corpus", str(corpus), "--runs-dir", str(runs)])
    err = " ".join(r.output.split())
    assert r.exit_code == 2, r.output
    assert why in err and len(r.output.strip().splitlines()) <= 2, r.output
    if args:                                                                      # the option and the item named
        assert err.startswith("error: --unet ") and args[-1][:12] in err, r.output
    assert not runs.exists()                                                      # nothing written


def test_resume_continues_a_network_and_refuses_its_changed_checkpoint(two_nets, tmp_path, monkeypatch):
    corpus, a, b, runs, _ = two_nets
    monkeypatch.setenv("LFMBENCH_NET_A_CHECKPOINT", "")
    whole = json.loads((runs / "net_a.json").read_text())
    killed = dict(whole, status="running", scenes=whole["scenes"][:1])              # a run killed after 1 sample
    out = tmp_path / "net_a.json"
    out.write_text(json.dumps(killed))
    before = out.read_bytes()
    ck = tmp_path / "u.pt"
    ck.write_bytes(b.read_bytes())                                                # not the weights it ran with
    r = _evaluate(["--unet", f"net_a={ck}", "--corpus", str(corpus), "--output", str(out)])
    msg = " ".join(r.output.split())
    assert r.exit_code == 2 and "'method.checkpoint' differs" in msg and str(out) in msg, r.output
    assert out.read_bytes() == before                                             # nothing written
    ck.write_bytes(a.read_bytes())                                                # the weights it ran with
    r = _evaluate(["--unet", f"net_a={ck}", "--corpus", str(corpus), "--output", str(out)])
    assert r.exit_code == 0 and "1 sample(s) recorded" in r.output, r.output
    d = json.loads(out.read_text())
    assert d["status"] == "complete" and _metrics(d) == _metrics(whole)
    assert d["method"]["checkpoint"]["file_sha256"] == file_sha256(a)
