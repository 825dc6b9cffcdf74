"""Resumed evaluation: a killed or interrupted run continued by the same command equals an uninterrupted run in
every score, simulating and scoring only the samples it misses; another evaluation's file is refused."""
from __future__ import annotations

import json
import re

import pytest
import torch
import typer
from typer.testing import CliRunner

from lfmbench import evaluation as ev
from lfmbench.baselines import get_method
from lfmbench.cli.evaluate import register as register_evaluate
from lfmbench.evaluation.benchmark import corpus_run_inputs, run_dataset_record, score_batches
from lfmbench.evaluation.provenance import file_sha256
from lfmbench.metrics import ScoreOptions
from tests.data.metrics.data import noisy_batches

#: Fields of a result that are measurements or provenance of the run (times, dates, command line, notes), not scores.
MEASURED = {"created", "runtime", "command", "method", "notes"}
METHODS = ("lpd_only", "spd_only")


class Counted:
    """A registered method that counts its calls."""

    def __init__(self, spec: str):
        self.fn, self.calls = get_method(spec), 0

    def __call__(self, batch):
        self.calls += 1
        return self.fn(batch)


@pytest.fixture(scope="module")
def setup(tmp_path_factory):
    """A 3-scene split, 2 draws per scene (6 samples); ``run(outputs, source, **kw)`` evaluates both methods like
    the CLI (batches of one); ``one``: the results of an uninterrupted run."""
    from tests.data.corpus.data import make_corpus

    tmp = tmp_path_factory.mktemp("resume")
    corpus = make_corpus(tmp / "corpus", n_scenes=3)
    ds, ident, cond = corpus_run_inputs(corpus, "all", 0, None, 2, frames=3, sensor="ovt", noise_streams="generator")
    n = len(ds)
    opts = ScoreOptions(perceptual=False, isp=None, sensor=ds.preset)  # no ISP: 15 s of colour set-up

    def run(outputs, source, fns=None, **kw):
        threads = torch.get_num_threads()
        torch.set_num_threads(1)
        try:
            return ev.evaluate_methods(fns or list(METHODS), source, method_specs=list(METHODS), outputs=outputs,
                                       options=opts, repeats=1, seeds={"dataset": 0}, progress=False, corpus=ident,
                                       dataset=run_dataset_record(ds, corpus, "all", n, None, 2, 3),
                                       scene_conditions=cond, **kw)
        finally:
            torch.set_num_threads(threads)

    one = run([tmp / f"one_{m}.json" for m in METHODS], lambda start: score_batches(ds, n, start=start))
    return tmp, corpus, ds, n, run, one


def _scores(d: dict) -> dict:
    """Every field of a result but the measured ones; sample records without their call time."""
    out = {k: v for k, v in d.items() if k not in MEASURED}
    out["scenes"] = [{k: v for k, v in s.items() if k != "call_ms"} for s in d["scenes"]]
    return out


def test_interrupted_and_killed_runs_resume_to_the_uninterrupted_result(setup, tmp_path, monkeypatch):
    from lfmbench.datasets.capture import LFMCaptureDataset

    tmp, _, ds, n, run, _ = setup
    outs = [tmp_path / f"{m}.json" for m in METHODS]

    def stopped_after(k):
        def source(start):
            for j, b in enumerate(score_batches(ds, n, start=start)):
                if j == k:
                    raise KeyboardInterrupt
                yield b
        return source

    with pytest.raises(ev.EvaluationInterrupted):
        run(outs, stopped_after(3))  # Ctrl-C after 3 batches: both files "interrupted", 3 samples each
    assert [json.loads(o.read_text())["status"] for o in outs] == ["interrupted"] * 2
    killed = json.loads(outs[1].read_text())  # spd_only's file as a run killed after its first sample leaves it
    killed["scenes"], killed["status"] = killed["scenes"][:1], "running"
    outs[1].write_text(json.dumps(killed))
    read = []
    orig = LFMCaptureDataset.__getitem__
    monkeypatch.setattr(LFMCaptureDataset, "__getitem__", lambda self, i: read.append(i) or orig(self, i))
    fns = [Counted(m) for m in METHODS]
    lines = []
    res = run(outs, lambda start: score_batches(ds, n, start=start), fns=fns, resume=True, log=lines.append)
    assert read == [1, 2, 3, 4, 5]  # the samples missing for at least one method, each read once
    assert [f.calls for f in fns] == [3, 5]  # each method scores only what it misses (timed before: no timing calls)
    assert any("resuming" in ln and "3 sample(s)" in ln for ln in lines)
    for m, o, r in zip(METHODS, outs, res):
        d, ref = json.loads(o.read_text()), json.loads((tmp / f"one_{m}.json").read_text())
        assert d["status"] == "complete" and len(d["scenes"]) == n and d["per_scene"] and r["status"] == "complete"
        assert _scores(d) == _scores(ref), m  # every score, CI, per-scene value and the breakdown: identical
        assert d["runtime"]["times_ms"] and any(x.startswith("resumed: ") for x in d["notes"])
    # a complete file of this evaluation: nothing read, nothing scored, the file left as it is
    read.clear()
    before = [o.read_bytes() for o in outs]
    lines.clear()
    run(outs, lambda start: score_batches(ds, n, start=start), fns=fns, resume=True, log=lines.append)
    assert read == [] and [o.read_bytes() for o in outs] == before
    assert len(lines) == 1 and f"{', '.join(METHODS)} skipped: complete result(s) of this evaluation in " \
        f"{outs[0].parent}" in lines[0], lines  # one line for all of them, naming the folder


def test_resume_refuses_another_evaluation_and_a_changed_checkpoint(tmp_path):
    out = tmp_path / "r.json"
    ck = tmp_path / "weights.pt"
    ck.write_bytes(b"first weights")

    def method(batch):
        return batch["gt"].clone()

    method.checkpoint_path = lambda: ck
    method.checkpoint_provenance = lambda: {"path": str(ck), "file_sha256": file_sha256(ck)}
    kw = dict(method_spec="m", output=out, options=ScoreOptions(isp=None), repeats=1, progress=False, resume=True,
              log=None)
    ev.evaluate(method, noisy_batches(2), seeds={"dataset": 0}, **kw)
    before = out.read_bytes()
    with pytest.raises(ev.run.ResumeError, match=rf"{re.escape(str(out))}.*'seeds.dataset' differs.*--no-resume"):
        ev.evaluate(method, noisy_batches(2), seeds={"dataset": 1}, **kw)
    ck.write_bytes(b"retrained weights")  # the same method name, other weights
    with pytest.raises(ev.run.ResumeError, match=rf"{re.escape(str(out))}.*'method.checkpoint' differs"):
        ev.evaluate(method, noisy_batches(2), seeds={"dataset": 0}, **kw)
    assert out.read_bytes() == before  # nothing written
    other = tmp_path / "notes.json"
    other.write_text('{"a": 1}')
    with pytest.raises(ev.run.ResumeError, match=rf"{re.escape(str(other))}: not an lfmbench-eval result"):
        ev.evaluate(method, noisy_batches(2), **dict(kw, output=other))
    res = ev.evaluate(method, noisy_batches(2), seeds={"dataset": 1}, **dict(kw, resume=False))
    assert res["seeds"] == {"dataset": 1} and json.loads(out.read_text())["seeds"] == {"dataset": 1}


def test_cli_resume_skips_a_complete_file_and_refuses_another_seed(setup, tmp_path):
    tmp, corpus, *_ = setup
    runs = tmp_path / "runs"
    runs.mkdir()
    (runs / "lpd_only.json").write_bytes((tmp / "one_lpd_only.json").read_bytes())
    app = typer.Typer()
    register_evaluate(app)
    args = ["evaluate", "-m", "lpd_only", "--corpus", str(corpus), "--split", "all", "--samples-per-scene", "2",
            "--runs-dir", str(runs), "--no-perceptual", "--isp", "none", "--repeats", "1"]
    threads = torch.get_num_threads()
    try:
        r = CliRunner().invoke(app, args)
        assert r.exit_code == 0, r.output
        assert "lpd_only skipped" in r.output and "6/6 scenes ok" in r.output
        r = CliRunner().invoke(app, [*args, "--seed", "1"])
        assert r.exit_code == 2
        msg = " ".join(r.output.split())
        assert "lpd_only.json" in msg and "'seeds.dataset' differs" in msg and "--no-resume" in msg
    finally:
        torch.set_num_threads(threads)
    assert (runs / "lpd_only.json").read_bytes() == (tmp / "one_lpd_only.json").read_bytes()
