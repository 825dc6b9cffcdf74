"""Corpus format 2 storage: HALF x per-layer 2^e, mantissa rounding, codecs, versions (lfmbench.corpus).

Expected values are computed independently of ``store_layer``: numpy's float16 cast (IEEE 754 binary16, round to
nearest even) and the scale exponent from ``floor(log2(peak))``.
"""
from __future__ import annotations

import hashlib
import io
import json
import math

import numpy as np
import OpenEXR
import pytest
from tests.data.corpus.data import BANDS, fake_frames, fake_meta, fake_scene

from lfmbench import corpus as C


def _expected_exponent(peak: float, bits: int) -> int:
    """Independent form of the scale rule: peak * 2^e in [2^(P-1), 2^P), P = 20 - 23 + bits."""
    p = C.HALF_PRECISION_RANGE_LOG2 - 23 + bits
    return p - int(math.floor(math.log2(peak))) - 1


def _half_roundtrip(x: np.ndarray, e: int) -> np.ndarray:
    """What plain HALF storage of x * 2^e reads back as, divided by 2^e (float64)."""
    return (x.astype(np.float64) * 2.0 ** e).astype(np.float16).astype(np.float64) / 2.0 ** e


def _write(root, storage, frames=None, meta=None):
    meta = meta or fake_meta()
    frames = frames or fake_frames(meta)
    w = C.CorpusWriter(root, dtype=storage)
    w.write_scene(meta["scene_id"], fake_scene(), meta, frames)
    w.write_splits(0)
    return meta, frames, w


# ------------------------------------------------------------------------------------------- rounding
def test_round_mantissa_matches_float16_and_bound():
    rng = np.random.default_rng(0)
    x = np.exp(rng.uniform(np.log(2.0 ** -14), np.log(6e4), 20000)).astype(np.float32)  # HALF normal range
    np.testing.assert_array_equal(C.round_mantissa(x, 10), x.astype(np.float16).astype(np.float32))
    for bits in (3, 5, 8, 20):
        r = C.round_mantissa(x, bits)
        rel = np.abs(r.astype(np.float64) - x) / x
        assert rel.max() <= 2.0 ** -(bits + 1) * (1 + 1e-6)
        assert rel.max() > 2.0 ** -(bits + 1) * 0.5  # really rounds (20000 draws reach the bound's half)
        # at most `bits` explicit mantissa bits are left
        assert not np.any(r.view(np.uint32) & np.uint32((1 << (23 - bits)) - 1))
    with pytest.raises(ValueError, match="bits"):
        C.round_mantissa(x, 0)


# ------------------------------------------------------------------------------------ float32 -> HALF
def test_float_to_half_is_numpys_cast_bit_for_bit():
    """The fast conversion against numpy's own float16 cast (IEEE 754 round to nearest even): every 4099th
    float32 bit pattern (both signs, subnormal, normal, overflow, inf) and the edge cases."""
    from lfmbench.corpus.storage import _half_parts

    pats = np.arange(0, 2 ** 32, 4099, dtype=np.uint64).astype(np.uint32).view(np.float32)
    edges = np.array([0.0, -0.0, 2.0 ** -25, 3 * 2.0 ** -26, 2.0 ** -24, 1.5 * 2.0 ** -24, 2.5 * 2.0 ** -24,
                      2.0 ** -14 - 2.0 ** -25, 2.0 ** -14 - 2.0 ** -26, 2.0 ** -14, 1 + 2.0 ** -11,
                      1 + 3 * 2.0 ** -11, 65504.0, 65519.99, 65520.0, 1e30, np.inf, -np.inf, -1e-6], np.float32)
    x = np.concatenate([pats, edges])
    finite_or_inf = ~np.isnan(x)
    with np.errstate(over="ignore", invalid="ignore"):
        want = x.astype(np.float16)
    bits, value = _half_parts(x)
    np.testing.assert_array_equal(bits[finite_or_inf], want.view(np.uint16)[finite_or_inf])
    np.testing.assert_array_equal(value[finite_or_inf].view(np.uint32),
                                  want.astype(np.float32)[finite_or_inf].view(np.uint32))  # exact HALF values
    assert np.isnan(bits.view(np.float16)[~finite_or_inf]).all() and np.isnan(value[~finite_or_inf]).all()
    np.testing.assert_array_equal(C.float_to_half(x[finite_or_inf].reshape(-1, 1)).view(np.uint16).ravel(),
                                  want.view(np.uint16)[finite_or_inf])


@pytest.mark.parametrize("storage", ["compact", "float16"])
def test_store_layer_equals_the_direct_formula_over_many_chunks(storage):
    """store_layer (chunked, fused) against the formula written out with numpy casts on the whole layer: a
    night-like layer (values over 12 decades, most of them HALF subnormals after scaling) larger than a chunk."""
    from lfmbench.corpus.storage import ENCODE_CHUNK

    rng = np.random.default_rng(5)
    x = np.exp(rng.uniform(np.log(1e-9), np.log(1e3), (3, 300, 301))).astype(np.float32)
    x[:, :40] = 0.0
    assert x.size > ENCODE_CHUNK
    st = C.STORAGES[storage]
    ls = C.store_layer(x, st)
    e = _expected_exponent(float(x.max()), st.bits)
    scaled = x * np.float32(2.0 ** e)
    if st.mantissa_bits is not None:
        scaled = C.round_mantissa(scaled, st.bits)
    want = scaled.astype(np.float16)
    assert ls.pixel_type == "float16" and ls.scale == 2.0 ** e
    np.testing.assert_array_equal(ls.data.view(np.uint16), want.view(np.uint16))
    d = np.abs(want.astype(np.float32) / np.float32(2.0 ** e) - x).astype(np.float64)
    total = x.sum(dtype=np.float64)
    assert ls.error == pytest.approx(d.sum() / total, rel=1e-9)
    assert ls.underflow_error == pytest.approx(d[scaled < C.HALF_MIN_NORMAL].sum() / total, rel=1e-9)
    assert (scaled < C.HALF_MIN_NORMAL).mean() > 0.3  # premise: many subnormals


# ------------------------------------------------------------------------------------------- scaled HALF
@pytest.mark.parametrize("level", [1e-6, 3.0, 2e5])  # night, day, above HALF_MAX (65504)
def test_scaled_half_equals_independent_float16(level):
    rng = np.random.default_rng(1)
    x = (level * rng.random((3, 6, 7))).astype(np.float32)
    ls = C.store_layer(x, C.Storage("float16", "zip"))
    e = _expected_exponent(float(x.max()), 10)
    assert ls.pixel_type == "float16" and ls.scale == 2.0 ** e and ls.fallback is None
    back = ls.data.astype(np.float64) / ls.scale
    np.testing.assert_array_equal(back, _half_roundtrip(x, e))
    inside = x >= x.max() * 2.0 ** -C.HALF_PRECISION_RANGE_LOG2
    assert (np.abs(back - x)[inside] / x[inside]).max() <= 2.0 ** -11
    assert ls.error == pytest.approx(np.abs(back - x).sum() / x.sum(dtype=np.float64), rel=1e-6)


def test_night_layer_plain_half_destroys_scaled_half_keeps():
    """Values 1e-7..1e-3 W sr^-1 m^-2 nm^-1: a plain float16 cast loses most digits, the scaled one keeps 11 bits."""
    rng = np.random.default_rng(2)
    x = np.exp(rng.uniform(np.log(1e-7), np.log(1e-3), (4, 16, 16))).astype(np.float32)
    plain = x.astype(np.float16).astype(np.float64)
    assert (np.abs(plain - x) / x).max() > 0.1  # premise: subnormal / flushed in plain HALF
    for st, bound in ((C.Storage("float16", "zip"), 2.0 ** -11), (C.STORAGES["compact"], 2.0 ** -6)):
        ls = C.store_layer(x, st)
        back = ls.data.astype(np.float64) / ls.scale
        assert ls.pixel_type == "float16"
        assert (np.abs(back - x) / x).max() <= bound * (1 + 1e-6)
        assert ls.underflow_error == 0.0  # 1e4 of range: nothing below HALF's normal range after scaling


def test_more_range_than_half_reports_and_falls_back():
    x = np.full((1, 1000, 1000), 6.5e-10, np.float32)  # 1e6 values 2^-31 below the peak
    x[0, 0, 0] = 1.0
    st = C.Storage("float16", "zip")
    e = _expected_exponent(1.0, 10)
    dim = x < 2.0 ** -14 / 2.0 ** e
    expected_under = float(np.abs(_half_roundtrip(x, e) - x)[dim].sum() / x.sum(dtype=np.float64))
    assert expected_under > st.max_underflow_error  # premise of this test
    ls = C.store_layer(x, st)
    assert ls.pixel_type == "float32" and ls.scale == 1.0 and "normal range" in ls.fallback
    np.testing.assert_array_equal(ls.data, x)  # FLOAT without rounding: exact
    # fewer dim values: stays HALF and reports the (small) measured underflow error
    y = x[:, :10].copy()
    ly = C.store_layer(y, st)
    dim_y = y < 2.0 ** -14 / 2.0 ** e
    want = float(np.abs(_half_roundtrip(y, e) - y)[dim_y].sum() / y.sum(dtype=np.float64))
    assert ly.pixel_type == "float16" and 0 < ly.underflow_error <= st.max_underflow_error
    assert ly.underflow_error == pytest.approx(want, rel=1e-5)
    # the writer aggregates: one note for the scene, naming the layer
    meta = fake_meta(width=1000, height=1000, groups={"skymap": {"flicker": False}}, frames=1)
    meta["lights"] = []
    frame = {"frame": 0, "static": {"skymap": {"short": np.repeat(x, 3, 0),
                                               "long": np.ones((3, 1000, 1000), np.float32)}}, "lights": {}}
    notes: list[str] = []
    files = dict(C.encode_scene("scene00000", {}, meta, [frame], dtype=st, notes=notes))
    assert len(notes) == 1 and "1 layer(s) stored FLOAT" in notes[0] and "skymap.exr [short]" in notes[0]
    assert json.loads(files["scenes/scene00000/meta.json"])["storage"] == {
        "format_version": C.FORMAT_VERSION, "dtype": "float16", "compression": "zip", "mantissa_bits": 10}


def test_all_zero_layers(tmp_path):
    meta = fake_meta()
    frames = fake_frames(meta)
    frames[0]["static"]["skymap"]["short"][:] = 0
    frames[1]["lights"]["otherlights"][0][2][:] = 0
    ls = C.store_layer(np.zeros((2, 3, 3), np.float32), "compact")
    assert ls.scale == 1.0 and ls.error == 0.0 and not ls.data.any()
    _write(tmp_path, "compact", frames, meta)
    c = C.Corpus(tmp_path)
    sid = meta["scene_id"]
    assert not c.read_static(sid, 0, "skymap", "short").any()
    assert not c.read_light_bins(sid, 1, "otherlights")[0][2].any()
    assert C.validate_corpus(tmp_path).ok


# ------------------------------------------------------------------------------------------- files
def test_compact_corpus_round_trip_and_independent_reader(tmp_path):
    meta, frames, w = _write(tmp_path, "compact")
    st = C.STORAGES["compact"]
    c = C.Corpus(tmp_path)
    sid = meta["scene_id"]
    assert c.manifest["version"] == C.FORMAT_VERSION == 3
    assert c.meta(sid)["storage"]["mantissa_bits"] == st.bits
    path = c.path(sid, 1, "headlights")
    f = OpenEXR.File(str(path), separate_channels=True)
    part = f.parts[0]
    assert part.header["compression"] == getattr(OpenEXR, C.COMPRESSIONS[st.compression])
    assert part.header["lfmbench_format_version"] == 3
    for win in ("short", "long"):
        ref = frames[1]["static"]["headlights"][win]
        scale = part.header[f"lfmbench_scale_{win}"]
        assert math.frexp(scale)[0] == 0.5  # a power of two
        px = np.stack([part.channels[f"{win}.{b:g}nm"].pixels for b in BANDS])
        assert px.dtype == np.float16
        indep = px.astype(np.float32) / np.float32(scale)
        got = c.read_static(sid, 1, "headlights", win)
        np.testing.assert_array_equal(got, indep)
        assert got.dtype == np.float32
        rel = np.abs(got.astype(np.float64) - ref) / ref
        assert rel.max() <= st.max_rel_rounding_error * (1 + 1e-6)
    lf = OpenEXR.File(str(c.path(sid, 0, "otherlights")), separate_channels=True)
    for p, (lid, box, arr) in zip(lf.parts, c.read_light_bins(sid, 0, "otherlights")):
        px = p.channels["bin01.550nm"].pixels
        np.testing.assert_array_equal(arr[1, 1], px.astype(np.float32) / np.float32(p.header["lfmbench_scale"]))
    assert C.validate_corpus(tmp_path).ok


def test_float32_storage_is_exact_and_zip(tmp_path):
    meta, frames, _ = _write(tmp_path, "float32")
    c = C.Corpus(tmp_path)
    np.testing.assert_array_equal(c.read_static(meta["scene_id"], 0, "skymap", "long"),
                                  frames[0]["static"]["skymap"]["long"])
    h = OpenEXR.File(str(c.path(meta["scene_id"], 0, "skymap")), header_only=True).parts[0].header
    assert h["compression"] == OpenEXR.ZIP_COMPRESSION and h["lfmbench_scale_long"] == 1.0


def _strip_to_version_1(root):
    """Turn a float32 corpus into what the version-1 writer produced: no format-2 attributes or meta entry."""
    man = json.loads((root / "manifest.json").read_text())
    for rel in list(man["files"]):
        p = root / rel
        if p.suffix == ".exr":
            f = OpenEXR.File(str(p), separate_channels=True)
            parts = []
            for part in f.parts:
                hdr = {k: v for k, v in part.header.items()
                       if not k.startswith(("lfmbench_scale", "lfmbench_format", "lfmbench_mantissa"))
                       and k not in ("channels", "name")}
                parts.append(OpenEXR.Part(hdr, {k: np.array(v.pixels) for k, v in part.channels.items()},
                                          part.name()))
            OpenEXR.File(parts).write(str(p))
        elif p.name == "meta.json":
            m = json.loads(p.read_text())
            del m["storage"]
            p.write_text(json.dumps(m))
        man["files"][rel] = hashlib.sha256(p.read_bytes()).hexdigest()
    man["version"] = 1
    (root / "manifest.json").write_text(json.dumps(man))


def test_old_version_1_corpus_still_reads(tmp_path):
    meta, frames, _ = _write(tmp_path, "float32")
    _strip_to_version_1(tmp_path)
    assert "lfmbench_scale_short" not in OpenEXR.File(
        str(tmp_path / "scenes/scene00000/f000/skymap.exr"), header_only=True).parts[0].header
    c = C.Corpus(tmp_path)
    sid = meta["scene_id"]
    np.testing.assert_array_equal(c.read_static(sid, 1, "skymap", "short"), frames[1]["static"]["skymap"]["short"])
    np.testing.assert_array_equal(c.read_light_bins(sid, 0, "otherlights")[1][2],
                                  frames[0]["lights"]["otherlights"][1][2])
    rep = C.validate_corpus(tmp_path)
    assert rep.ok, rep.errors
    # a new writer may add scenes to it; the corpus becomes version 3 and both scenes read
    m2 = fake_meta("scene00001")
    w = C.CorpusWriter(tmp_path)
    w.write_scene("scene00001", fake_scene("scene00001"), m2, fake_frames(m2, seed=5))
    c2 = C.Corpus(tmp_path)
    assert c2.manifest["version"] == 3 and c2.scenes == ["scene00000", "scene00001"]
    np.testing.assert_array_equal(c2.read_static(sid, 1, "skymap", "short"), frames[1]["static"]["skymap"]["short"])


def test_newer_version_refused_naming_file(tmp_path):
    meta, _, _ = _write(tmp_path, "compact")
    mpath = tmp_path / "manifest.json"
    man = json.loads(mpath.read_text())
    mpath.write_text(json.dumps(dict(man, version=5)))
    with pytest.raises(C.CorpusFileError, match=r"manifest\.json.*version 5 is newer"):
        C.Corpus(tmp_path)
    rep = C.validate_corpus(tmp_path)
    assert not rep.ok and "version 5" in rep.errors[0] and "manifest.json" in rep.errors[0]
    with pytest.raises(C.CorpusFileError, match="unsupported corpus format version 'x'"):
        mpath.write_text(json.dumps(dict(man, version="x")))
        C.Corpus(tmp_path)
    mpath.write_text(json.dumps(man))
    # one EXR file of a newer version
    p = tmp_path / "scenes/scene00000/f001/skymap.exr"
    _set_header(p, "lfmbench_format_version", 7)
    with pytest.raises(C.CorpusFileError, match=r"f001/skymap\.exr.*version 7 is newer"):
        C.Corpus(tmp_path).read_static(meta["scene_id"], 1, "skymap", "long")
    assert any("f001/skymap.exr" in e and "version 7" in e for e in C.validate_corpus(tmp_path).errors)
    # a meta.json announcing a newer storage format
    mp = tmp_path / "scenes/scene00000/meta.json"
    m = json.loads(mp.read_text())
    m["storage"]["format_version"] = 6
    mp.write_text(json.dumps(m))
    with pytest.raises(C.CorpusFileError, match=r"meta\.json storage\.format_version.*version 6"):
        C.Corpus(tmp_path).meta(meta["scene_id"])


def _set_header(p, key, value):
    """Rewrite the static EXR file ``p`` with header attribute ``key`` set to ``value`` (pixels unchanged)."""
    part = OpenEXR.File(str(p), separate_channels=True).parts[0]
    hdr = {k: v for k, v in part.header.items() if k not in ("channels", "name")}
    hdr[key] = value
    OpenEXR.File([OpenEXR.Part(hdr, {k: np.array(v.pixels) for k, v in part.channels.items()}, "static")]).write(str(p))


def test_bad_scale_attribute_is_reported(tmp_path):
    meta, _, _ = _write(tmp_path, "compact")
    p = tmp_path / "scenes/scene00000/f000/headlights.exr"
    _set_header(p, "lfmbench_scale_long", 3.0)
    with pytest.raises(C.CorpusFileError, match=r"f000/headlights\.exr.*lfmbench_scale_long = 3\.0.*power of two"):
        C.Corpus(tmp_path).read_static(meta["scene_id"], 0, "headlights", "long")
    errs = C.validate_corpus(tmp_path).errors
    assert any("headlights.exr" in e and "lfmbench_scale_long" in e for e in errs)


def test_storage_arguments_checked():
    with pytest.raises(ValueError, match="dtype must be one of"):
        C.CorpusWriter("/nonexistent/x", dtype="float64")
    with pytest.raises(ValueError, match="compression must be one of"):
        C.Storage("float16", "b44")  # lossy on HALF: not for corpora
    with pytest.raises(ValueError, match="mantissa_bits"):
        C.Storage("float16", "zip", 11)
    assert C.Storage("float16", "b44", allow_lossy_codec=True).compression == "b44"
    assert C.resolve_storage("compact") is C.STORAGES[C.DEFAULT_STORAGE]


def test_pxr24_and_piz_codecs_round_trip():
    rng = np.random.default_rng(3)
    win = {w: rng.random((3, 5, 6)).astype(np.float32) for w in C.STATIC_WINDOWS}
    for comp in ("piz", "pxr24", "dwab", "zips"):
        data = C.encode_static_exr(win, BANDS, dtype=C.Storage("float16", comp))
        f = OpenEXR.File(io.BytesIO(data), separate_channels=True)
        px = f.parts[0].channels["long.550nm"].pixels
        e = _expected_exponent(float(win["long"].max()), 10)
        np.testing.assert_array_equal(px.astype(np.float64) / f.parts[0].header["lfmbench_scale_long"],
                                      _half_roundtrip(win["long"][1], e))  # lossless on HALF
