"""A render resume hashes only the files whose state the validation cache does not know (render_tools.ray_jobs.
CompleteScenes): the first resume hashes every committed file once, the next none; a file changed since is hashed
and its scene rendered again; the keys of ``lfmbench validate`` stay in the cache."""
from __future__ import annotations

import json

from lfmbench import corpus as C
from lfmbench.corpus import meta as M
from lfmbench.corpus import validate_cache as VC
from tests.data.render.data import ARGS, run


def test_resume_hashes_each_unchanged_file_once(tmp_path, fake, monkeypatch):
    monkeypatch.setattr(VC, "RACY_S", 0.0)  # the files just written count as settled (no 2 s wait in a test)
    hashed: list[str] = []
    real = M.sha256_file

    def counting(p, *a, **k):
        hashed.append(str(p))
        return real(p, *a, **k)

    monkeypatch.setattr(M, "sha256_file", counting)
    out = tmp_path / "c"
    assert run("--out", str(out), "--scenes", "2", "--seed", "7", *ARGS).exit_code == 0
    n_files = len(json.loads((out / "manifest.json").read_text())["files"])
    assert C.validate_corpus(out, cache=True).ok  # validate fills the cache with its file and scene keys
    keys_after_validate = VC.default_cache_path(out).read_bytes()
    hashed.clear()
    r = run("--out", str(out), "--scenes", "2", "--seed", "7", *ARGS)
    assert r.exit_code == 0 and "2 skipped" in r.output
    assert hashed == []  # every file known from validate's check: none read again
    assert VC.default_cache_path(out).read_bytes() == keys_after_validate  # validate's keys kept
    # a file changed since: hashed, found different, its scene (only) rendered again
    p = out / "scenes/scene00001/f001/aux.exr"
    p.write_bytes(p.read_bytes()[:-10])
    r = run("--out", str(out), "--scenes", "2", "--seed", "7", *ARGS)
    assert r.exit_code == 0 and "1 rendered" in r.output and fake[-1] == "scene00001"
    assert [h for h in hashed if h.endswith("aux.exr")] and len(hashed) < n_files
    # no validate in between: the first resume hashes the new scene's files once, the next one none
    hashed.clear()
    assert "2 skipped" in run("--out", str(out), "--scenes", "2", "--seed", "7", *ARGS).output
    first = len(hashed)
    hashed.clear()
    assert "2 skipped" in run("--out", str(out), "--scenes", "2", "--seed", "7", *ARGS).output
    assert 0 < first and hashed == []
    assert C.validate_corpus(out).ok
