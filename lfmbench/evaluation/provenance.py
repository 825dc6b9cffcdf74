"""Provenance stored with every result: versions, git revision, device, and the corpus identity.

- :func:`versions`, :func:`git_revision`, :func:`device_name`: what produced a result.
- :func:`corpus_identity`: what it was computed on: the SHA-256 of the corpus ``manifest.json`` bytes, the SHA-256
  of the scored scenes' files (their manifest checksums), the corpus format version and the SHA-256 of the frozen
  test draws (``test_params.json``) when the corpus has them. ``lfmbench leaderboard`` refuses to rank results
  whose identities differ; it compares the scored scenes' files, not the whole manifest, so a protocol corpus
  scored after ``--split test`` and again after its training scenes were added stays comparable.
"""
from __future__ import annotations

import hashlib
import json
import os
import platform
import re
import subprocess
from pathlib import Path

import torch

#: Corpus files whose bytes identify what a result was computed on.
MANIFEST_NAME = "manifest.json"
TEST_PARAMS_NAME = "test_params.json"


def file_sha256(path: str | Path) -> str:
    """Hex SHA-256 of a file's bytes (read in 1 MiB blocks); not a regular file: ``NotRegularFileError``."""
    from lfmbench.fileio import open_regular  # noqa: PLC0415

    h = hashlib.sha256()
    with open_regular(path) as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def corpus_identity(root: str | Path, scene_ids: list[str] | None = None) -> dict:
    """``{"path", "manifest_sha256", "scenes_sha256", "format_version", "test_params_sha256"}`` of a corpus.

    ``scenes_sha256``: SHA-256 of the canonical JSON ``{scene_id: {file: sha256}}`` of ``scene_ids`` (the scenes a
    result scores) from the manifest's file checksums; None without ``scene_ids``. ``test_params_sha256`` is None
    until the test split's draws are frozen (first use of the split).

    Raises:
        FileNotFoundError: naming the missing ``manifest.json``.
        ValueError: naming a manifest that is not a JSON object, or a scene it does not list.
    """
    root = Path(root)
    man = root / MANIFEST_NAME
    if not man.is_file():
        raise FileNotFoundError(f"corpus {root}: {MANIFEST_NAME} not found (not an lfmbench corpus?)")
    from lfmbench.fileio import loads_json, read_bytes  # noqa: PLC0415

    raw = read_bytes(man, "manifest", "manifest_bytes")
    doc = loads_json(raw, str(man))
    if not isinstance(doc, dict):
        raise ValueError(f"{man}: must hold a JSON object")
    scenes_sha = None
    if scene_ids is not None:
        files = doc.get("files") if isinstance(doc.get("files"), dict) else {}
        per: dict[str, dict] = {str(s): {} for s in scene_ids}
        for rel, sha in files.items():
            parts = str(rel).split("/")
            if len(parts) > 2 and parts[1] in per:
                per[parts[1]]["/".join(parts[2:])] = sha
        missing = [s for s, f in per.items() if not f]
        if missing:
            raise ValueError(f"{man}: no files listed for scene(s) {missing[:3]}")
        scenes_sha = hashlib.sha256(json.dumps(per, sort_keys=True).encode()).hexdigest()
    tp = root / TEST_PARAMS_NAME
    return {"path": str(root), "manifest_sha256": hashlib.sha256(raw).hexdigest(), "scenes_sha256": scenes_sha,
            "format_version": doc.get("version"),
            "test_params_sha256": file_sha256(tp) if tp.is_file() else None}


def _lfmbench_version() -> str:
    try:
        from importlib.metadata import version

        return version("lfmbench")
    except Exception:
        return "unknown"


def git_revision(path: str | Path | None = None) -> dict:
    """``{'commit': sha or 'unknown', 'dirty': bool | None}`` of the repository holding ``path`` (this package)."""
    where = Path(path or Path(__file__).resolve().parents[1])
    try:
        sha = subprocess.run(["git", "-C", str(where), "rev-parse", "HEAD"], capture_output=True, text=True,
                             timeout=10).stdout.strip()
        st = subprocess.run(["git", "-C", str(where), "status", "--porcelain", "--untracked-files=no"],
                            capture_output=True, text=True, timeout=10)
        return {"commit": sha if re.fullmatch(r"[0-9a-f]{40}", sha) else "unknown",
                "dirty": bool(st.stdout.strip()) if st.returncode == 0 else None}
    except (OSError, subprocess.SubprocessError):
        return {"commit": "unknown", "dirty": None}


def device_name(device: str | torch.device = "cpu") -> str:
    """Human-readable device name: the GPU's name, or the CPU model from /proc/cpuinfo."""
    dev = torch.device(device)
    if dev.type == "cuda" and torch.cuda.is_available():
        return torch.cuda.get_device_name(dev)
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return f"{line.split(':', 1)[1].strip()} ({os.cpu_count()} cores, {torch.get_num_threads()} threads)"
    except OSError:
        pass
    return platform.processor() or platform.machine()


def versions(perceptual: bool, cd_per_unit: float | None = None) -> dict:
    """Versions stored with every result: lfmbench, torch, numpy, python, metric versions, cvvdp config."""
    import numpy as np

    from lfmbench.metrics import hdr, metric_versions

    return {"lfmbench": _lfmbench_version(), "torch": torch.__version__, "numpy": np.__version__,
            "python": platform.python_version(), "metrics": metric_versions(),
            "cvvdp": hdr.cvvdp_config(cd_per_unit) if perceptual else None}
