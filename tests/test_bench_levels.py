"""The device-path benchmark's corpus from rendered electron levels (``benchmarks/bench_device_path.py --levels``,
``benchmarks/_device_corpus.py``): the band grouping keeps the wavelength integral, and a scene built from a
template reads back as the template."""
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
import _device_corpus as B  # noqa: E402

from lfmbench.corpus import Corpus, CorpusWriter  # noqa: E402
from tests.data.corpus.data import fake_frames, fake_meta, fake_scene  # noqa: E402

BANDS31 = [400.0 + 10 * i for i in range(31)]


def test_grouped_bands_keep_the_wavelength_integral():
    rng = np.random.default_rng(3)
    a = rng.random((2, 31, 5, 7)).astype(np.float32) * np.logspace(-6, 2, 31, dtype=np.float32)[:, None, None]
    g = B._group_bands(a, BANDS31)
    assert g.shape == (2, 4, 5, 7)
    # sum over the 31 bands of radiance x 10 nm == sum over the 4 groups of radiance x 77.5 nm (float32 rounding)
    np.testing.assert_allclose(g.astype(np.float64).sum(1) * B.LEVEL_BAND_WIDTH, a.astype(np.float64).sum(1) * 10.0,
                               rtol=1e-6)
    # the first group is the mean over 400-470 nm scaled by 80 / 77.5 nm
    np.testing.assert_allclose(g[:, 0], a[:, :8].astype(np.float64).sum(1) * 10 / 77.5, rtol=1e-6)
    with pytest.raises(ValueError, match="31 bands"):
        B._group_bands(a[:, :30], BANDS31[:30])


def test_a_scene_built_from_a_template_reads_back_as_the_template(tmp_path):
    meta = fake_meta("scene00000", width=12, height=8, frames=2, bins=3, bands=BANDS31, n_lights=2)
    w = CorpusWriter(tmp_path / "rendered")
    w.write_scene("scene00000", fake_scene(), meta, fake_frames(meta, seed=1))
    w.write_splits(0)
    lv_path = B.extract_levels(tmp_path / "rendered", 4, tmp_path / "levels.npz")
    lv = np.load(lv_path)
    assert int(lv["templates"]) == 1 and lv["s0_boxes"].shape == (2, 4)
    src = Corpus(tmp_path / "rendered")
    want = B._group_bands(src.read_static(src.scenes[0], 0, "headlights", "long")
                          + src.read_static(src.scenes[0], 0, "skymap", "long"), BANDS31)
    out = B.make_corpus(tmp_path / "bench", 2, levels=lv_path)
    c = Corpus(out)
    assert c.scenes == ["scene00000", "scene00001"]
    m = c.meta("scene00001")
    assert (m["height"], m["width"], m["bands_nm"], m["band_width_nm"]) == (8, 12, list(B.LEVEL_BANDS), 77.5)
    got = c.read_static("scene00001", 1, "skymap", "long")
    # float16 in the npz (2^-11 relative), then the corpus's own storage: its mantissa bits, rounded to nearest
    bits = int(m["storage"]["mantissa_bits"])
    np.testing.assert_allclose(got, want, rtol=2.0 ** -11 + 2.0 ** -(bits + 1) * 1.01, atol=1e-7)
    assert not np.allclose(got, np.flip(want, -1), rtol=2.0 ** -11 + 2.0 ** -(bits + 1) * 1.01)
    lights = c.read_light_bins("scene00001", 0, "otherlights")
    assert [box for _i, box, _a in lights] == [tuple(b) for b in lv["s0_boxes"].tolist()]
