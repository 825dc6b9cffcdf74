"""The README's training example runs as written, on a tiny corpus: the same code, with the corpus path, the
crop (the tiny scenes are smaller than 64 px), the workers (none: a test spawns no processes) and the epochs cut."""
from __future__ import annotations

import re
from pathlib import Path

import torch

from lfmbench.fileio import load_yaml
from tests.data.corpus.data import H, W, make_corpus

README = Path(__file__).resolve().parents[1] / "README.md"


def test_readme_dataloader_example_runs(tmp_path):
    text = README.read_text(encoding="utf-8")
    code = next(c for c in re.findall(r"```python\n(.*?)```", text, re.S) if "DataLoader(" in c)
    assert '"corpus"' in code and "crop=64" in code and "num_workers=2" in code and "range(10)" in code
    # the README renders its corpus with --profile small: crop 64 must fit that profile's frames
    assert "lfmbench render --out corpus --scenes 6 --profile small" in text
    small = load_yaml(Path(__file__).resolve().parents[1] / "render_tools" / "configs" / "render_profiles.yaml")["small"]
    assert min(small["width"], small["height"]) >= 64
    root = make_corpus(tmp_path / "corpus", n_scenes=2)
    crop = min(8, H, W)
    code = (code.replace('"corpus"', repr(str(root))).replace("crop=64", f"crop={crop}")
            .replace("num_workers=2", "num_workers=0").replace("range(10)", "range(1)")
            .replace('split="train"', 'split="all"'))
    ns: dict = {}
    exec(compile(code, "README.md", "exec"), ns)
    x, target = ns["x"], ns["target"]
    assert target.shape[-2:] == (crop, crop) and target.shape[1:3] == (3, 1)
    assert all(t.shape == target.shape for t in x) and torch.isfinite(target).all()
