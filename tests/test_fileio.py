import errno
import json
import os

import pytest

from lfmbench import fileio


def test_failed_write_keeps_old_file_and_leaves_no_temporary(tmp_path, monkeypatch):
    p = tmp_path / "a.json"
    fileio.atomic_write_json(p, {"v": 1})

    def full_disk(fd):
        raise OSError(errno.ENOSPC, "No space left on device")
    monkeypatch.setattr(os, "fsync", full_disk)
    with pytest.raises(fileio.AtomicWriteError, match="a.json: disk full"):
        fileio.atomic_write_json(p, {"v": 2})
    assert json.loads(p.read_text()) == {"v": 1}
    assert [q.name for q in tmp_path.iterdir()] == ["a.json"]


def test_strict_json_and_mode_bits(tmp_path):
    with pytest.raises(ValueError):
        fileio.atomic_write_json(tmp_path / "nan.json", {"x": float("nan")})
    assert not list(tmp_path.iterdir())
    p = tmp_path / "ok.txt"
    digest = fileio.atomic_write_text(p, "hello")
    assert digest == "2cf24dba5fb0a30e26e83b2ac5b9e29e1b161e5c1fa7425e73043362938b9824"
    mask = os.umask(0)
    os.umask(mask)
    assert (p.stat().st_mode & 0o777) == (0o666 & ~mask)


def test_figure_and_torch_round_trip(tmp_path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import torch

    fig, ax = plt.subplots()
    ax.plot([0, 1], [1, 0])
    png = fileio.atomic_save_figure(fig, tmp_path / "f.png", dpi=50)
    assert png.read_bytes()[:4] == b"\x89PNG"
    pt = fileio.atomic_torch_save({"w": torch.arange(3)}, tmp_path / "x.pt")
    assert torch.equal(torch.load(pt)["w"], torch.arange(3))
