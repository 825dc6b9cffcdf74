"""A URL given where lfmbench needs a file-system path is refused with one line naming the argument, and nothing
is created (before: ``render --out s3://bucket/corpus`` rendered into a local folder ``s3:``)."""
from __future__ import annotations

import pytest
from typer.testing import CliRunner

from lfmbench.fileio import url_error, url_scheme


def test_url_scheme():
    for url, scheme in (("s3://bucket/corpus", "s3"), ("gs://b", "gs"), ("HTTP://h/x", "http"),
                        ("s3:/bucket/corpus", "s3"),  # what pathlib.Path makes of s3://bucket/corpus
                        ("ray+file://x", "ray+file"), ("file:///tmp/x", "file")):
        assert url_scheme(url) == scheme
    for path in ("/tmp/corpus", "corpus", "./a:b/c", "C:/data", "runs/s3_corpus", "a:b"):
        assert url_scheme(path) is None and url_error("--out", path) is None
    assert url_error("--out", "s3://b/c").startswith("--out s3://b/c: a s3:// URL")


@pytest.mark.parametrize("args", [
    ["render", "--out", "s3://bucket/corpus", "--scenes", "1"],
    ["train", "--corpus", "gs://bucket/corpus"],
    ["train", "--corpus", "corpus", "--out", "s3://bucket/unet.pt"],
    ["validate", "http://host/corpus"],
    ["import-isetlfm", "src", "s3://bucket/corpus"],
    ["paper-figures", "--out", "s3://bucket/img"],
    ["demo", "--out", "gs://bucket/demo"],
])
def test_cli_refuses_url_paths(args, tmp_path, monkeypatch):
    from lfmbench.cli import app

    monkeypatch.chdir(tmp_path)
    r = CliRunner().invoke(app, args)
    name = next(a for a in args if "://" in a)
    flag = args[args.index(name) - 1] if args[args.index(name) - 1].startswith("-") else None
    assert r.exit_code == 2, r.output
    lines = r.output.strip().splitlines()
    assert len(lines) == 1 and "URL" in lines[0] and "POSIX" in lines[0], r.output
    if flag:
        assert flag in lines[0]
    assert list(tmp_path.iterdir()) == []  # no folder 's3:' or 'gs:' made
