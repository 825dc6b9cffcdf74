"""``lfmbench plot --unet NAME=CHECKPOINT``: trained networks shown by name beside the methods, in the order given;
a bad item is refused naming ``--unet`` and the item before anything is written."""
from __future__ import annotations

import pytest
from typer.testing import CliRunner


@pytest.fixture(scope="module")
def corpus_and_nets(tmp_path_factory):
    """A tiny corpus and two untrained U-Nets (2 channels, depth 1) with different random weights."""
    from tests.data.baselines.data import random_unets
    from tests.data.corpus.data import make_corpus

    root = tmp_path_factory.mktemp("plot_unets")
    return make_corpus(root / "c", n_scenes=1), random_unets(root)


def _plot(args, monkeypatch, rows, shown=None):
    """Run ``lfmbench plot ARGS``, appending the figure's row labels (the y labels of its first column) to
    ``rows`` as it is saved; ``shown``: a dict that gets the sample and the outputs the figure is made of."""
    import lfmbench.datasets.plot as dplot
    import lfmbench.fileio as fileio
    from lfmbench.cli import app

    save, plot_sample = fileio.atomic_save_figure, dplot.plot_sample

    def record(fig, path, **kw):
        rows.extend(ax.get_ylabel() for ax in fig.axes if ax.get_ylabel())
        return save(fig, path, **kw)

    def keep(sample, preset, outputs, **kw):
        if shown is not None:
            shown.update(sample=sample, outputs=dict(outputs))
        return plot_sample(sample, preset, outputs, **kw)

    monkeypatch.setattr(fileio, "atomic_save_figure", record)
    monkeypatch.setattr(dplot, "plot_sample", keep)
    return CliRunner().invoke(app, ["plot", *args])


def test_two_networks_are_shown_by_name_after_the_methods(corpus_and_nets, tmp_path, monkeypatch):
    corpus, (a, b) = corpus_and_nets
    for env in ("LFMBENCH_NET_B_CHECKPOINT", "LFMBENCH_NET_A_CHECKPOINT"):
        monkeypatch.setenv(env, "")                                    # set by the command; restored afterwards
    import torch

    from lfmbench.baselines.unet import load_checkpoint
    from lfmbench.datasets import collate_samples

    rows: list[str] = []
    shown: dict = {}
    png = tmp_path / "s.png"
    r = _plot(["--corpus", str(corpus), "--split", "all", "--frames", "1", "--dpi", "20", "--out", str(png),
               "--unet", f"net_b={b}", "-m", "lpd_only", "--unet", f"net_a={a}"], monkeypatch, rows, shown)
    assert r.exit_code == 0, r.output
    assert png.read_bytes()[:4] == b"\x89PNG"
    assert rows[-3:] == ["lpd_only", "net_b", "net_a"], rows      # the methods, then the networks as given
    assert "ground truth, lpd_only, net_b, net_a" in r.output
    batch = collate_samples([shown["sample"]])
    with torch.no_grad():                                          # each row is its own network's output
        for name, ck in (("net_a", a), ("net_b", b)):
            assert torch.equal(shown["outputs"][name], load_checkpoint(ck)(dict(batch))[0]), name
    assert not torch.equal(shown["outputs"]["net_a"], shown["outputs"]["net_b"])


@pytest.mark.parametrize("item, why", [
    ("net_a", "give NAME=CHECKPOINT"),                     # no checkpoint
    ("Net-A={a}", "give NAME=CHECKPOINT"),                 # not snake_case
    ("unet={a}", "give NAME=CHECKPOINT"),                  # a registered method's name
    ("lpd_only={a}", "give NAME=CHECKPOINT"),              # a registered method, here also a --method row
    ("net_a={a} --unet net_a={a}", "give NAME=CHECKPOINT"),  # the name of an earlier --unet row
    ("net_a={missing}", "no such file"),
    ("net_a={notweights}", "cannot be read as weights"),   # a file that is no checkpoint
])
def test_a_bad_network_is_refused_naming_the_option_and_nothing_is_written(corpus_and_nets, tmp_path,
                                                                          monkeypatch, item, why):
    corpus, (a, _) = corpus_and_nets
    monkeypatch.setenv("LFMBENCH_NET_A_CHECKPOINT", "")
    (tmp_path / "junk.pt").write_text("not weights")
    item = item.format(a=a, missing=tmp_path / "missing.pt", notweights=tmp_path / "junk.pt")
    png = tmp_path / "s.png"
    r = _plot(["--corpus", str(corpus), "--split", "all", "--frames", "1", "-m", "lpd_only", "--out", str(png),
               *(x for i in item.split(" --unet ") for x in ("--unet", i))], monkeypatch, [])
    err = " ".join(r.output.split())
    assert r.exit_code == 2, r.output
    assert err.startswith("error: --unet ") and item[:12] in err and why in err, r.output
    assert len(r.output.strip().splitlines()) <= 2 and not png.exists()
