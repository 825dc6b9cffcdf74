"""Format version 3: a light's bins stored over the pixels that change from bin to bin, plus a ``steady<id>`` part
for the pixels that hold the same value in every bin (a wet road's reflection traced once, a lamp's padded box).

The reader must give back exactly what the writer was given (FLOAT storage), or that within the HALF rounding
bound (compact storage); the split must be the one ``docs/guide/corpus-format.md`` 6.2 defines (checked pixel by pixel
against a brute-force loop); version-2 layouts keep reading; ``lfmbench validate`` names a broken layout.
"""
from __future__ import annotations

import json

import numpy as np
import OpenEXR
import pytest
from tests.data.corpus.data import BANDS, fake_frames, fake_meta, fake_scene

from lfmbench import corpus as C

K = 4


def _reflection_light(rng, h=7, w=9, lamp=(1, 2, 3, 5)):
    """(K, C, h, w): a lamp whose bins differ inside ``lamp`` (a sub-box), a 'reflection' below it that is the
    same in every bin, zeros in a corner (the padded box)."""
    C_ = len(BANDS)
    arr = np.zeros((K, C_, h, w), np.float32)
    refl = (rng.random((C_, h - 3, w - 2)) * 0.3).astype(np.float32)
    arr[:, :, 3:, 1:w - 1] = refl  # the same in every bin
    y0, x0, y1, x1 = lamp
    arr[:, :, y0:y1, x0:x1] = (1 + rng.random((K, C_, y1 - y0, x1 - x0))).astype(np.float32)
    return arr


def test_split_steady_is_exact_and_bounds_the_changing_pixels():
    rng = np.random.default_rng(3)
    for trial in range(20):
        arr = _reflection_light(rng)
        if trial % 3 == 1:  # a single changing pixel in one band and one bin
            arr = np.repeat(arr[:1], K, axis=0)
            arr[2, 1, 5, 6] += 1.0
        if trial % 3 == 2:  # nothing changes
            arr = np.repeat(arr[:1], K, axis=0)
        bb, sb, steady = C.split_steady(arr)
        # brute force: the pixels whose value differs between two bins in some band
        h, w = arr.shape[2:]
        changing = [(y, x) for y in range(h) for x in range(w)
                    if any(arr[k, c, y, x] != arr[0, c, y, x] for k in range(K) for c in range(len(BANDS)))]
        if changing:
            ys, xs = zip(*changing)
            assert bb == (min(ys), min(xs), max(ys) + 1, max(xs) + 1)
        else:
            assert bb == (0, 0, 1, 1)
        inside = np.zeros((h, w), bool)
        inside[bb[0]:bb[2], bb[1]:bb[3]] = True
        for k in range(K):  # arr[k] == steady + (arr[k] inside the bins' box)
            np.testing.assert_array_equal(arr[k], steady + np.where(inside, arr[k], 0))
        assert not steady[:, inside].any()
        nz = steady.any(axis=0)
        if nz.any():
            ys, xs = np.nonzero(nz)
            assert sb == (ys.min(), xs.min(), ys.max() + 1, xs.max() + 1)
        else:
            assert sb is None


def _meta_frames(rng, frames=2):
    meta = fake_meta(width=16, height=12, frames=frames, bins=K, n_lights=2)
    meta["lights"][0]["bbox"] = [[2, 3, 9, 12]] * frames      # 7 x 9: a lamp and its reflection
    meta["lights"][1]["bbox"] = [[0, 12, 3, 16]] * frames     # 3 x 4: random bins (nothing steady)
    fr = fake_frames(meta)
    for f in fr:
        f["lights"]["otherlights"][0] = (0, (2, 3, 9, 12), _reflection_light(rng))
    return meta, fr


def _parts(path):
    return {p.name(): p for p in OpenEXR.File(str(path), separate_channels=True).parts}


def _steady_bins(rng, h=7, w=9, box=(1, 2, 3, 5), vary=True):
    """A SteadyBins (what the renderer hands the writer for a wet road's grown crop) and its (K, C, h, w) array
    built independently: steady outside ``box``, the bins inside it."""
    C_ = len(BANDS)
    steady = (rng.random((C_, h, w)) * 0.3).astype(np.float32)
    steady[:, :2, :2] = 0.0  # a zero corner (the grown box's padding)
    y0, x0, y1, x1 = box
    bins = (1 + rng.random((K, C_, y1 - y0, x1 - x0))).astype(np.float32)
    if not vary:
        bins[:] = bins[:1]
    arr = np.repeat(steady[None], K, axis=0)
    arr[:, :, y0:y1, x0:x1] = bins
    return C.SteadyBins(steady, box, bins), arr


@pytest.mark.parametrize("box,vary", [((1, 2, 3, 5), True), ((0, 0, 7, 9), True), ((4, 6, 7, 9), True),
                                      ((2, 3, 4, 4), False), ((0, 0, 0, 0), True)])
def test_steady_bins_stand_for_their_array_and_encode_the_same_bytes(box, vary):
    """SteadyBins (the renderer's form of a grown crop) is the array it stands for, splits as split_steady splits
    that array (same boxes, same values) and encodes to the same bytes, in both storages."""
    rng = np.random.default_rng(sum(box) + vary)
    sb, arr = _steady_bins(rng, box=box, vary=vary)
    assert sb.shape == arr.shape and sb.dtype == np.float32
    np.testing.assert_array_equal(np.asarray(sb), arr)
    np.testing.assert_array_equal(sb.window(2, 1, 6, 8), arr[:, :, 2:6, 1:8])
    got, want = sb.split(), C.split_steady(arr)
    assert got[:2] == want[:2]
    np.testing.assert_array_equal(got[2], want[2])
    for dtype in ("float32", "compact"):
        assert C.encode_lights_exr([(3, (2, 4, 9, 13), sb)], BANDS, K, 12, 16, dtype=dtype) == \
            C.encode_lights_exr([(3, (2, 4, 9, 13), arr)], BANDS, K, 12, 16, dtype=dtype)


def test_steady_bins_checked_like_arrays():
    rng = np.random.default_rng(5)
    for where in ("steady", "bins"):
        sb, _ = _steady_bins(rng)
        getattr(sb, where)[0, 1, 1] = np.nan
        with pytest.raises(C.CorpusValueError, match="light3: radiance contains NaN"):
            C.encode_lights_exr([(3, (2, 4, 9, 13), sb)], BANDS, K, 12, 16)
    sb, _ = _steady_bins(rng)
    with pytest.raises(ValueError, match=r"expected shape \(K=4"):
        C.encode_lights_exr([(3, (2, 4, 9, 14), sb)], BANDS, K, 12, 16)
    with pytest.raises(ValueError, match="do not fit"):
        C.SteadyBins(sb.steady, (1, 2, 3, 6), sb.bins)


def test_float32_round_trip_is_exact_and_stores_fewer_values(tmp_path):
    rng = np.random.default_rng(0)
    meta, frames = _meta_frames(rng)
    sid = meta["scene_id"]
    w = C.CorpusWriter(tmp_path / "v3", dtype="float32")
    w.write_scene(sid, fake_scene(), meta, frames)
    w.write_splits(0)
    c = C.Corpus(tmp_path / "v3")
    assert c.manifest["version"] == 3
    for n in range(2):
        got = c.read_light_bins(sid, n, "otherlights")
        want = frames[n]["lights"]["otherlights"]
        assert [(lid, box) for lid, box, _ in got] == [(lid, tuple(box)) for lid, box, _ in want]
        for (_, _, a), (_, _, b) in zip(got, want):
            np.testing.assert_array_equal(a, b)
        sub = c.read_light_bins(sid, n, "otherlights", bands=[700.0])  # a band subset assembles the same way
        np.testing.assert_array_equal(sub[0][2], want[0][2][:, 2:3])
    parts = _parts(c.path(sid, 0, "otherlights"))
    assert sorted(parts) == ["light0", "light1", "steady0"]  # light 1 changes everywhere: no steady part
    win = parts["light0"].header["dataWindow"]
    assert (tuple(win[0]), tuple(win[1])) == ((3 + 2, 2 + 1), (3 + 4, 2 + 2))  # the lamp's sub-box (x, y), inclusive
    assert parts["light0"].header["lfmbench_nparts"] == 3
    stored = sum(ch.pixels.size for p in parts.values() for ch in p.channels.values())
    assert stored < 0.45 * K * len(BANDS) * (7 * 9 + 3 * 4)  # vs every light's K bins over its whole box
    assert C.validate_corpus(tmp_path / "v3").ok


def test_compact_within_the_rounding_bound_and_version_2_layout_reads_alike(tmp_path):
    rng = np.random.default_rng(1)
    meta, frames = _meta_frames(rng, frames=1)
    sid = meta["scene_id"]
    C.CorpusWriter(tmp_path / "c", dtype="compact").write_scene(sid, fake_scene(), meta, frames)
    st = C.STORAGES["compact"]
    [(_, _, a), _] = C.Corpus(tmp_path / "c").read_light_bins(sid, 0, "otherlights")
    ref = frames[0]["lights"]["otherlights"][0][2]
    big = ref >= ref.max() * 2.0 ** -20
    assert np.all(np.abs(a[big] - ref[big]) <= st.max_rel_rounding_error * ref[big] * (1 + 1e-6))
    np.testing.assert_array_equal(a[~big], 0)
    # the version-2 layout (every light's K bins over its box) is still a valid file: same radiance back
    lights = frames[0]["lights"]["otherlights"]
    p = tmp_path / "c" / "scenes" / sid / "f000" / "otherlights.exr"
    p.write_bytes(C.encode_lights_exr(lights, BANDS, K, 12, 16, dtype="float32", steady=False))
    assert sorted(_parts(p)) == ["light0", "light1"]
    c2 = C.Corpus(tmp_path / "c")
    for (_, box, x), (_, wbox, y) in zip(c2.read_light_bins(sid, 0, "otherlights"), lights):
        assert box == tuple(wbox)
        np.testing.assert_array_equal(x, y)


def _write_parts(path, parts):
    OpenEXR.File(parts).write(str(path))


def _light_part(name, channels, box, W=16, H=12):
    y0, x0, y1, x1 = box
    h = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage,
         "displayWindow": ((0, 0), (W - 1, H - 1)), "dataWindow": ((x0, y0), (x1 - 1, y1 - 1)),
         "lfmbench_format_version": 3}
    return OpenEXR.Part(h, channels, name)


@pytest.mark.parametrize("case", ["steady_alone", "steady_outside_bbox", "steady_bin_channels"])
def test_validate_and_reader_name_a_broken_layout(tmp_path, case):
    rng = np.random.default_rng(2)
    meta, frames = _meta_frames(rng, frames=1)
    sid = meta["scene_id"]
    root = tmp_path / "c"
    w = C.CorpusWriter(root, dtype="float32")
    w.write_scene(sid, fake_scene(), meta, frames)
    w.write_splits(0)
    p = root / "scenes" / sid / "f000" / "otherlights.exr"
    parts = _parts(p)
    keep = {n: {k: np.array(v.pixels) for k, v in q.channels.items()} for n, q in parts.items()}
    win = {n: q.header["dataWindow"] for n, q in parts.items()}
    box = {n: (int(w[0][1]), int(w[0][0]), int(w[1][1]) + 1, int(w[1][0]) + 1) for n, w in win.items()}
    if case == "steady_alone":
        names = ["light1", "steady0"]
    else:
        names = ["light0", "light1", "steady0"]
        if case == "steady_outside_bbox":  # one column left of the light's bbox (2, 3, 9, 12)
            y0, x0, y1, x1 = box["steady0"]
            box["steady0"] = (y0, 2, y1, 2 + (x1 - x0))
        else:  # a steady part with bin channels
            keep["steady0"] = {f"bin00.{b:g}nm": v for b, v in zip(BANDS, keep["steady0"].values())}
    _write_parts(p, [_light_part(n, keep[n], box[n]) for n in names])
    man = json.loads((root / "manifest.json").read_text())
    man["files"][p.relative_to(root).as_posix()] = C.sha256_file(p)
    (root / "manifest.json").write_text(json.dumps(man))
    errs = C.validate_corpus(root).errors
    want = {"steady_alone": ["'steady0' without its part 'light0'", "has no part 'light0'"],
            "steady_outside_bbox": ["part 'steady0' data window (5, 2, 9, 9) is not inside meta.json bbox[0]"],
            "steady_bin_channels": ["part 'steady0': missing channels ['steady.400nm'",
                                    "part 'steady0': unexpected channels ['bin00.400nm'"]}[case]
    assert len(errs) == len(want), errs
    for x in want:
        assert any("f000/otherlights.exr" in e and x in e for e in errs), (x, errs)
    if case != "steady_bin_channels":
        with pytest.raises(C.CorpusChannelError, match="otherlights.exr.*(without its part|not inside its box)"):
            C.Corpus(root).read_light_bins(sid, 0, "otherlights")
