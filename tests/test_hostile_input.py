"""Hostile and unlucky input, second round (issue 27; docs/fault-catalogue.md): outputs that are not regular files,
billion-laughs YAML, deep JSON, EXR bombs, foreign folders, two writers, untrustworthy scores, scale limits.

Tiny generated files only; nothing here renders, and nothing allocates more than a few MB.
"""
from __future__ import annotations

import errno
import json
import os
import stat
import threading
import time

import pytest
from typer.testing import CliRunner

from lfmbench import fileio, limits
from lfmbench.cli import app


def _one_line(r):
    """A refused CLI run: exit 2, no traceback, one non-empty line on stderr (rich may wrap it: joined)."""
    assert r.exit_code == 2, r.output
    assert "Traceback" not in r.output and isinstance(r.exception, SystemExit), r.output
    return " ".join(r.output.split())


# ------------------------------------------------------------ 1. outputs never replace what the path points at
def test_output_symlink_is_written_through_not_replaced(tmp_path):
    target = tmp_path / "real" / "result.json"
    target.parent.mkdir()
    target.write_text("{}")
    link = tmp_path / "link.json"
    link.symlink_to(target)
    fileio.atomic_write_json(link, {"v": 2})
    assert link.is_symlink() and os.readlink(link) == str(target)
    assert json.loads(target.read_text()) == {"v": 2}
    assert sorted(p.name for p in target.parent.iterdir()) == ["result.json"]  # no temporary left


def test_output_fifo_is_written_directly_not_replaced(tmp_path):
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    got = []
    reader = threading.Thread(target=lambda: got.append(open(fifo, "rb").read()))
    reader.start()
    fileio.atomic_write_text(fifo, "hello")
    reader.join(10)
    assert got == [b"hello"]
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)  # still the FIFO, not a regular file in its place
    t0 = time.monotonic()  # no reader: an error naming the path at once, not a hang
    with pytest.raises(fileio.AtomicWriteError, match="could not write .*pipe"):
        fileio.atomic_write_text(fifo, "again")
    assert time.monotonic() - t0 < 5 and stat.S_ISFIFO(os.lstat(fifo).st_mode)
    assert fileio.writable_error(fifo) is None


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="needs Linux /dev/full")
def test_write_error_of_a_device_reaches_the_exit_code(tmp_path):
    st = os.stat("/dev/full")
    with pytest.raises(fileio.AtomicWriteError, match="could not write /dev/full: disk full") as e:
        fileio.atomic_write_text("/dev/full", "x")
    assert e.value.errno == errno.ENOSPC
    assert os.stat("/dev/full").st_rdev == st.st_rdev and stat.S_ISCHR(os.stat("/dev/full").st_mode)
    assert not [p for p in os.listdir("/dev") if p.startswith(fileio.TMP_PREFIX)]
    # the CLI: the leaderboard's outputs
    from tests.data.evaluation.data import write_result

    run = write_result(tmp_path / "a.json")
    r = CliRunner().invoke(app, ["leaderboard", str(run), "--markdown", "/dev/full", "--plot",
                                 str(tmp_path / "p.png"), "--json", str(tmp_path / "l.json")])
    out = _one_line(r)
    assert "/dev/full" in out and "disk full" in out
    assert stat.S_ISCHR(os.stat("/dev/full").st_mode)


def test_evaluate_output_symlink_and_device(tmp_path, monkeypatch):
    """``evaluate -o`` a symbolic link writes through it; ``-o /dev/full`` exits 2 naming it (it exited 0)."""
    from tests.data.corpus.data import make_corpus

    corpus = make_corpus(tmp_path / "c", n_scenes=1)
    target = tmp_path / "keep" / "r.json"
    target.parent.mkdir()
    link = tmp_path / "r.json"
    link.symlink_to(target)
    base = ["evaluate", "--method", "lpd_only", "--corpus", str(corpus), "--split", "all", "--repeats", "1",
            "--warmup", "0", "--no-perceptual"]
    r = CliRunner().invoke(app, [*base, "-o", str(link)])
    assert r.exit_code == 0, r.output
    assert link.is_symlink() and json.loads(target.read_text())["status"] == "complete"
    if os.path.exists("/dev/full"):
        out = _one_line(CliRunner().invoke(app, [*base, "-o", "/dev/full"]))
        assert "/dev/full" in out and "disk full" in out
        assert stat.S_ISCHR(os.stat("/dev/full").st_mode)


# ------------------------------------------------------------------- 5. YAML: billion laughs, long values
def _laughs(levels: int, width: int = 10) -> str:
    """A YAML "billion laughs": ``width ** levels`` strings after alias expansion, ``levels * width`` aliases."""
    lines = ['a0: &a0 "lol"']
    for i in range(1, levels + 1):
        lines.append(f"a{i}: &a{i} [" + ", ".join([f"*a{i - 1}"] * width) + "]")
    return "\n".join(lines) + "\n"


def _yaml_readers():
    from lfmbench import sensor
    from lfmbench.baselines import unet
    from lfmbench.datasets.pwm import load_pwm_config
    from lfmbench.evaluation.conditions import load_bins
    from render_tools import jobs, protocol, scene

    return {"sensor preset": sensor.load_preset, "PWM config": load_pwm_config, "condition bins": load_bins,
            "render profile": jobs.load_profile, "protocol": protocol.load_protocol,
            "U-Net config": unet.load_config, "scene config": scene.load_config}


def test_billion_laughs_yaml_is_refused_by_every_reader(tmp_path):
    bomb = tmp_path / "bomb.yaml"
    bomb.write_text(_laughs(6))  # 10^6 nodes after expansion, 60 aliases
    for what, read in _yaml_readers().items():
        t0 = time.monotonic()
        with pytest.raises(ValueError) as e:
            read(bomb)
        msg = str(e.value)
        assert time.monotonic() - t0 < 5, what
        assert "bomb.yaml" in msg and "yaml_nodes" in msg and len(msg) < 400 and "\n" not in msg, (what, msg)
    many = tmp_path / "aliases.yaml"
    many.write_text("a: &a 1\nb: [" + ", ".join(["*a"] * 150) + "]\n")
    with pytest.raises(fileio.InputFileError, match="aliases.yaml: .*yaml_aliases=100"):
        fileio.load_yaml(many)
    limits.set_limit("yaml_aliases", 200)
    try:
        assert len(fileio.load_yaml(many)["b"]) == 150  # raised explicitly: read
    finally:
        limits.set_limit("yaml_aliases", None)


def test_yaml_error_quotes_only_a_prefix_of_a_bad_value(tmp_path):
    from lfmbench import sensor

    data = fileio.load_yaml(sensor.PRESET_DIR / "ovt.yaml")
    data["pixel_pitch_m"] = "x" * 100_000
    p = tmp_path / "long.yaml"
    import yaml

    p.write_text(yaml.safe_dump(data))
    with pytest.raises(ValueError) as e:
        sensor.load_preset(p)
    assert "long.yaml" in str(e.value) and len(str(e.value)) < 400, str(e.value)[:500]


def test_cli_limit_option_raises_a_limit_and_refuses_nonsense(tmp_path):
    r = CliRunner().invoke(app, ["--limit", "nonsense=3", "protocols"])
    assert r.exit_code == 2 and "--limit" in r.output and "json_bytes" in r.output
    r = CliRunner().invoke(app, ["--limit", "yaml_nodes=-1", "protocols"])
    assert r.exit_code == 2 and "positive integer" in r.output


# ------------------------------------------------------------------------------------------ 10. deep JSON
def test_deep_json_manifest_and_results_are_one_line(tmp_path):
    from tests.data.corpus.data import make_corpus

    deep = "[" * 100_000 + "]" * 100_000
    corpus = make_corpus(tmp_path / "c", n_scenes=1)
    (corpus / "manifest.json").write_text(deep)
    r = CliRunner().invoke(app, ["validate", str(corpus)])
    assert r.exit_code == 1 and "Traceback" not in r.output and "json_depth" in r.output, r.output
    assert isinstance(r.exception, SystemExit)
    (tmp_path / "deep.json").write_text(deep)
    out = _one_line(CliRunner().invoke(app, ["leaderboard", str(tmp_path / "deep.json")]))
    assert "deep.json" in out and "json_depth" in out
    with pytest.raises(fileio.InputFileError, match="json_depth"):
        fileio.loads_json("[" * 70 + "]" * 70, "x.json")  # deeper than 64 but below Python's recursion limit
    for bad in ("[NaN]", "[Infinity]", "[1e400]", "[" + "9" * 5000 + "]"):
        with pytest.raises(fileio.InputFileError, match="x.json: not valid JSON"):
            fileio.loads_json(bad, "x.json")
