"""Corpus format: EXR encoding, reader, writer, atomic writes, resume, splits (lfmbench.corpus)."""
from __future__ import annotations

import errno
import json
import os

import numpy as np
import OpenEXR
import pytest
from tests.data.corpus.data import BANDS, disk_full_after, fake_frames, fake_meta, fake_scene

from lfmbench import corpus as C


@pytest.fixture
def one_scene(tmp_path):
    meta = fake_meta()
    frames = fake_frames(meta)
    w = C.CorpusWriter(tmp_path / "c", dtype="float32")  # lossless: exact comparisons below
    w.write_scene(meta["scene_id"], fake_scene(), meta, frames)
    w.write_splits(0)
    return tmp_path / "c", meta, frames


# ------------------------------------------------------------------------------------------ naming
def test_channel_names():
    assert C.band_channel("short", 400) == "short.400nm"
    assert C.band_channel("long", 402.5) == "long.402.5nm"
    assert C.bin_prefix(0, 8) == "bin00"
    assert C.bin_prefix(7, 8) == "bin07"
    assert C.bin_prefix(5, 101) == "bin005"
    assert C.static_channels("short", [400, 410]) == ["short.400nm", "short.410nm"]
    assert C.bin_channels(2, [500])[1] == ["bin01.500nm"]
    with pytest.raises(ValueError, match="window"):
        C.static_channels("medium", BANDS)
    with pytest.raises(ValueError, match="wavelength"):
        C.band_channel("short", -3)


# --------------------------------------------------------------------------------------- round trip
def test_round_trip_exact(one_scene):
    root, meta, frames = one_scene
    c = C.Corpus(root)
    sid = meta["scene_id"]
    assert c.scenes == [sid]
    assert c.meta(sid)["bands_nm"] == BANDS
    assert c.scene(sid) == fake_scene()
    for n, fr in enumerate(frames):
        for g, wins in fr["static"].items():
            for w in ("short", "long"):
                got = c.read_static(sid, n, g, w)
                assert got.dtype == np.float32 and got.shape == (3, 8, 12)
                np.testing.assert_array_equal(got, wins[w])
        got = c.read_light_bins(sid, n, "otherlights")
        want = fr["lights"]["otherlights"]
        assert [g[0] for g in got] == [w[0] for w in want]
        for (gid, gbox, garr), (wid, wbox, warr) in zip(got, want):
            assert tuple(gbox) == tuple(wbox)
            np.testing.assert_array_equal(garr, warr)
        aux = c.read_aux(sid, n)
        for k in C.AUX_CHANNELS:
            np.testing.assert_array_equal(aux[k], fr["aux"][k])
    assert np.isinf(c.read_aux(sid, 0, ["depth.Z"])["depth.Z"][0, 0])


def test_band_subset_and_errors(one_scene):
    root, meta, frames = one_scene
    c = C.Corpus(root)
    sid = meta["scene_id"]
    got = c.read_static(sid, 1, "skymap", "long", bands=[700, 400])
    np.testing.assert_array_equal(got, frames[1]["static"]["skymap"]["long"][[2, 0]])
    lb = c.read_light_bins(sid, 0, "otherlights", bands=[550])
    np.testing.assert_array_equal(lb[0][2], frames[0]["lights"]["otherlights"][0][2][:, 1:2])
    with pytest.raises(ValueError, match="bands: 450"):
        c.read_static(sid, 0, "skymap", "short", bands=[450])
    with pytest.raises(ValueError, match="group 'signals'"):
        c.read_static(sid, 0, "signals", "short")
    with pytest.raises(ValueError, match="frame"):
        c.read_static(sid, 2, "skymap", "short")
    with pytest.raises(ValueError, match="read_light_bins"):
        c.read_static(sid, 0, "otherlights", "short")
    with pytest.raises(ValueError, match="read_static"):
        c.read_light_bins(sid, 0, "skymap")
    with pytest.raises(KeyError, match="nope"):
        c.meta("nope")
    with pytest.raises(ValueError, match="names"):
        c.read_aux(sid, 0, ["depth.X"])


def test_exr_layout_read_by_openexr_directly(one_scene):
    """Independent check of the on-disk layout with the bare OpenEXR API (what another tool would see)."""
    root, meta, frames = one_scene
    f = OpenEXR.File(str(root / "scenes" / meta["scene_id"] / "f001" / "otherlights.exr"), separate_channels=True)
    assert [p.name() for p in f.parts] == ["light0", "light1"]
    for part, (lid, (y0, x0, y1, x1), arr) in zip(f.parts, frames[1]["lights"]["otherlights"]):
        (dx0, dy0), (dx1, dy1) = part.header["dataWindow"]
        assert (int(dy0), int(dx0), int(dy1) + 1, int(dx1) + 1) == (y0, x0, y1, x1)
        (wx0, wy0), (wx1, wy1) = part.header["displayWindow"]
        assert (int(wx1) + 1, int(wy1) + 1) == (12, 8)
        assert part.header["compression"] == OpenEXR.ZIP_COMPRESSION
        assert part.channels["bin02.700nm"].pixels.dtype == np.float32
        np.testing.assert_array_equal(part.channels["bin02.700nm"].pixels, arr[2, 2])
    s = OpenEXR.File(str(root / "scenes" / meta["scene_id"] / "f000" / "headlights.exr"), separate_channels=True)
    assert len(s.parts) == 1
    assert sorted(s.parts[0].channels) == sorted(C.static_channels("short", BANDS) + C.static_channels("long", BANDS))


def test_cache_decodes_once(one_scene, monkeypatch):
    root, meta, _ = one_scene
    calls = []
    real = C.read_exr
    monkeypatch.setattr(C.reader, "read_exr", lambda p, **kw: calls.append(p) or real(p, **kw))
    c = C.Corpus(root, cache_size=2)
    c.read_static(meta["scene_id"], 0, "headlights", "short")
    c.read_static(meta["scene_id"], 0, "headlights", "long")
    assert len(calls) == 1
    c0 = C.Corpus(root, cache_size=0)
    c0.read_static(meta["scene_id"], 0, "headlights", "short")
    c0.read_static(meta["scene_id"], 0, "headlights", "long")
    assert len(calls) == 3


def test_empty_flicker_group(tmp_path):
    meta = fake_meta()
    frames = fake_frames(meta)
    frames[0]["lights"]["otherlights"] = []  # no light visible in frame 0
    for lt in meta["lights"]:
        lt["bbox"][0] = None  # meta.json says so too
    w = C.CorpusWriter(tmp_path)
    w.write_scene(meta["scene_id"], fake_scene(), meta, frames)
    w.write_splits(0)
    c = C.Corpus(tmp_path)
    assert c.read_light_bins(meta["scene_id"], 0, "otherlights") == []
    assert len(c.read_light_bins(meta["scene_id"], 1, "otherlights")) == 2
    assert C.validate_corpus(tmp_path).ok


# ------------------------------------------------------------------------------------------------ HALF
def test_half_storage_scales_above_half_max(tmp_path):
    """A peak above HALF_MAX (65504) no longer forces FLOAT: the layer's 2^e scale brings it into range."""
    meta = fake_meta()
    frames = fake_frames(meta)
    frames[0]["static"]["headlights"]["short"][0, 0, 0] = 1.0e5
    w = C.CorpusWriter(tmp_path, dtype="float16")
    w.write_scene(meta["scene_id"], fake_scene(), meta, frames)
    assert w.notes == []  # no FLOAT fallback
    w.write_splits(0)
    c = C.Corpus(tmp_path)
    for g, win in (("headlights", "short"), ("skymap", "long")):
        got = c.read_static(meta["scene_id"], 0, g, win)
        ref = frames[0]["static"][g][win]
        rel = np.abs(got.astype(np.float64) - ref) / ref
        inside = ref >= ref.max() * 2.0 ** -C.HALF_PRECISION_RANGE_LOG2
        assert rel[inside].max() <= 2.0 ** -11  # binary16 round-to-nearest: half an ulp = 2^-11 relative
        assert not np.array_equal(got, ref)
    assert c.read_static(meta["scene_id"], 0, "headlights", "short")[0, 0, 0] == pytest.approx(1.0e5, rel=2.0 ** -11)
    f = OpenEXR.File(str(c.path(meta["scene_id"], 0, "headlights")), separate_channels=True)
    assert f.parts[0].channels["short.400nm"].pixels.dtype == np.float16
    assert f.parts[0].header["lfmbench_scale_short"] < 1  # 2^e with e < 0
    assert C.validate_corpus(tmp_path).ok


# ---------------------------------------------------------------------------------------- bad input
def test_writer_rejects_bad_radiance(tmp_path):
    meta = fake_meta()
    for bad, msg in ((np.nan, "NaN"), (-1.0, "negative"), (np.inf, "inf")):
        frames = fake_frames(meta)
        frames[1]["static"]["skymap"]["long"][1, 2, 3] = bad
        w = C.CorpusWriter(tmp_path)
        with pytest.raises(C.CorpusValueError, match=f"f001/skymap.exr.*{msg}"):
            w.write_scene(meta["scene_id"], fake_scene(), meta, frames)
        assert meta["scene_id"] not in C.CorpusWriter(tmp_path).scenes


def test_writer_rejects_inconsistent_frames(tmp_path):
    meta = fake_meta()
    w = C.CorpusWriter(tmp_path)
    frames = fake_frames(meta)
    frames[0]["lights"]["otherlights"][0] = (7, (1, 1, 4, 3), frames[0]["lights"]["otherlights"][0][2])
    with pytest.raises(ValueError, match="light ids \\[7\\]"):
        w.write_scene(meta["scene_id"], fake_scene(), meta, frames)
    frames = fake_frames(meta)
    del frames[1]["static"]["skymap"]
    with pytest.raises(ValueError, match="do not match meta.json groups"):
        w.write_scene(meta["scene_id"], fake_scene(), meta, frames)
    frames = fake_frames(meta)
    frames[0]["static"]["headlights"]["short"] = frames[0]["static"]["headlights"]["short"][:, :4]
    with pytest.raises(ValueError, match="shapes differ"):
        w.write_scene(meta["scene_id"], fake_scene(), meta, frames)
    frames = fake_frames(meta)
    with pytest.raises(ValueError, match="frames \\[0\\]"):
        w.write_scene(meta["scene_id"], fake_scene(), meta, frames[:1])
    lid, box, arr = fake_frames(meta)[0]["lights"]["otherlights"][0]
    with pytest.raises(ValueError, match="outside"):
        C.encode_lights_exr([(lid, (5, 1, 9, 3), arr)], BANDS, 3, 8, 12)
    with pytest.raises(ValueError, match="scene_id"):
        w.write_scene("bad/id", fake_scene(), dict(meta, scene_id="bad/id"), fake_frames(meta))


@pytest.mark.parametrize("change, field", [
    (lambda m: m["camera"].update(speed_mps=-3.0), "speed_mps"),
    (lambda m: m["timing"].update(long_exposure_s=0.02), "frame time"),
    (lambda m: m["timing"].update(short_exposure_s=0.012), "longer than long_exposure_s"),
    (lambda m: m["timing"].update(capture_window_s=0.005), "cover"),
    (lambda m: m["timing"].update(bins=0), "bins"),
    (lambda m: m.update(bands_nm=[500, 400, 600]), "bands_nm"),
    (lambda m: m.update(width=0), "width"),
    (lambda m: m.pop("timing"), "timing"),
    (lambda m: m["lights"][0].update(group="nosuch"), "group"),
    (lambda m: m["groups"].update(aux={"flicker": False}), "aux"),
])
def test_validate_meta_impossible_values(change, field):
    meta = fake_meta()
    C.validate_meta(meta)
    change(meta)
    with pytest.raises(ValueError, match=field):
        C.validate_meta(meta, "x/meta.json")


# ---------------------------------------------------------------------------------------- reader errors
def test_reader_errors_name_the_file(one_scene):
    root, meta, _ = one_scene
    sid = meta["scene_id"]
    with pytest.raises(C.CorpusNotFoundError, match="lfmbench render"):
        C.Corpus(root / "nothing")
    p = root / "scenes" / sid / "f000" / "skymap.exr"
    data = p.read_bytes()
    p.write_bytes(b"not an exr" * 10)
    with pytest.raises(C.CorpusFileError, match="skymap.exr"):
        C.Corpus(root).read_static(sid, 0, "skymap", "short")
    p.unlink()
    with pytest.raises(C.CorpusFileError, match="missing.*skymap.exr"):
        C.Corpus(root).read_static(sid, 0, "skymap", "short")
    q = root / "scenes" / sid / "f000" / "otherlights.exr"
    q.write_bytes(q.read_bytes()[:-40])  # truncated: last part unreadable
    with pytest.raises(C.CorpusFileError, match="otherlights.exr"):
        C.Corpus(root).read_light_bins(sid, 0, "otherlights")
    p.write_bytes(data)
    C.Corpus(root).read_static(sid, 0, "skymap", "short")


def _rewrite_static(path, fn):
    f = OpenEXR.File(str(path), separate_channels=True)
    ch = {k: np.array(v.pixels) for k, v in f.parts[0].channels.items()}
    ch = fn(ch)
    h = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    OpenEXR.File(h, ch).write(str(path))


def test_reader_checks_values_and_channels(one_scene):
    root, meta, _ = one_scene
    sid = meta["scene_id"]
    p = root / "scenes" / sid / "f001" / "headlights.exr"

    def nan(ch):
        ch["long.550nm"][2, 2] = np.nan
        return ch
    _rewrite_static(p, nan)
    c = C.Corpus(root)
    c.read_static(sid, 1, "headlights", "short")  # other window is clean
    with pytest.raises(C.CorpusValueError, match="headlights.exr.*NaN"):
        c.read_static(sid, 1, "headlights", "long")
    assert C.Corpus(root, check_values=False).read_static(sid, 1, "headlights", "long").shape == (3, 8, 12)

    def neg(ch):
        ch["long.550nm"][2, 2] = -0.5
        return ch
    _rewrite_static(p, neg)
    with pytest.raises(C.CorpusValueError, match="negative"):
        C.Corpus(root).read_static(sid, 1, "headlights", "long")

    def drop(ch):
        del ch["short.400nm"]
        return ch
    _rewrite_static(p, drop)
    with pytest.raises(C.CorpusChannelError, match="headlights.exr.*short.400nm"):
        C.Corpus(root).read_static(sid, 1, "headlights", "short")


# ------------------------------------------------------------------------------- atomicity and resume
def _no_tmp(root):
    return not [p for p in root.rglob(C.TMP_PREFIX + "*")]


def test_disk_full_leaves_valid_corpus(tmp_path, monkeypatch):
    root = tmp_path / "c"
    w = C.CorpusWriter(root)
    m0 = fake_meta("scene00000")
    w.write_scene("scene00000", fake_scene(), m0, fake_frames(m0))
    w.write_splits(0)
    manifest_before = (root / "manifest.json").read_bytes()
    real_fsync = disk_full_after(monkeypatch, 3)  # a few files go through, then the disk is full
    m1 = fake_meta("scene00001")
    with pytest.raises(C.CorpusWriteError, match="disk full") as ei:
        w.write_scene("scene00001", fake_scene(), m1, fake_frames(m1))
    assert ei.value.errno == errno.ENOSPC
    monkeypatch.setattr(os, "fsync", real_fsync)
    assert (root / "manifest.json").read_bytes() == manifest_before
    assert _no_tmp(root)
    rep = C.validate_corpus(root)
    assert rep.ok, rep.errors
    assert C.Corpus(root).scenes == ["scene00000"]
    # resume: the scene can be written afterwards
    w2 = C.CorpusWriter(root)
    assert not w2.is_complete("scene00001")
    w2.write_scene("scene00001", fake_scene(), m1, fake_frames(m1))
    w2.write_splits(0)
    assert C.validate_corpus(root).ok


def test_interrupted_scene_is_not_recorded(tmp_path):
    root = tmp_path / "c"
    meta = fake_meta()
    frames = fake_frames(meta)

    def gen():
        yield frames[0]
        raise KeyboardInterrupt
    w = C.CorpusWriter(root)
    with pytest.raises(KeyboardInterrupt):
        w.write_scene(meta["scene_id"], fake_scene(), meta, gen())
    assert (root / "scenes" / meta["scene_id"] / "f000" / "skymap.exr").is_file()  # written, not committed
    man = json.loads((root / "manifest.json").read_text())
    assert man["scenes"] == [] and man["files"] == {}
    assert not C.CorpusWriter(root).is_complete(meta["scene_id"])
    # a stray temp file from a killed process is cleaned by the next writer
    (root / "scenes" / meta["scene_id"] / f"{C.TMP_PREFIX}x.exr").write_bytes(b"partial")
    w = C.CorpusWriter(root)
    assert _no_tmp(root)
    w.write_scene(meta["scene_id"], fake_scene(), meta, frames)
    assert w.is_complete(meta["scene_id"])


# ---------------------------------------------------------------------------- threaded scene writer
def _serial_files(meta, frames, dtype="compact"):
    return dict(C.encode_scene(meta["scene_id"], fake_scene(), meta, frames, dtype=dtype))


def test_threaded_writer_writes_what_the_serial_writer_writes(tmp_path):
    meta = fake_meta(frames=3)
    frames = fake_frames(meta)
    want = _serial_files(meta, frames)
    notes: list[str] = []
    with C.ThreadedSceneWriter(tmp_path, meta["scene_id"], fake_scene(), meta, dtype="compact", notes=notes) as w:
        for fr in frames:
            w.put(fr)
        hashes = w.close()
    assert not w.alive
    assert sorted(hashes) == sorted(want)
    for rel, data in want.items():
        assert (tmp_path / rel).read_bytes() == data, rel
        assert hashes[rel] == C.sha256_file(tmp_path / rel)
    assert _no_tmp(tmp_path)


def test_parallel_encoding_gives_the_same_files_and_notes():
    """encode_scene with a thread pool: the files of a frame encoded in parallel, yielded in the serial order
    with the same bytes; the FLOAT-fallback note of the scene is the same."""
    from concurrent.futures import ThreadPoolExecutor

    meta = fake_meta(frames=3)
    frames = fake_frames(meta)
    frames[1]["static"]["skymap"]["short"][:] = 1e-44  # too dim for any HALF scale: stored FLOAT, one note
    serial_notes: list[str] = []
    serial = list(C.encode_scene(meta["scene_id"], fake_scene(), meta, frames, notes=serial_notes))
    notes: list[str] = []
    with ThreadPoolExecutor(3) as pool:
        par = list(C.encode_scene(meta["scene_id"], fake_scene(), meta, frames, notes=notes, executor=pool))
    assert [r for r, _ in par] == [r for r, _ in serial]
    assert all(a == b for (_, a), (_, b) in zip(par, serial))
    assert notes == serial_notes and len(notes) == 1 and "skymap.exr [short]" in notes[0]


def test_threaded_writer_hands_over_one_frame_at_a_time(tmp_path, monkeypatch):
    """put() returns only once the worker has taken the frame, i.e. finished encoding the one before."""
    import threading

    from lfmbench.corpus import scene_files as W

    meta = fake_meta(frames=3)
    frames = fake_frames(meta)
    gate = threading.Event()
    real = W.encode_static_exr

    def slow(*a, **k):
        gate.wait(10)
        return real(*a, **k)
    monkeypatch.setattr(W, "encode_static_exr", slow)
    w = C.ThreadedSceneWriter(tmp_path, meta["scene_id"], fake_scene(), meta)
    w.put(frames[0])  # taken at once: the worker was idle
    t = threading.Thread(target=w.put, args=(frames[1],))
    t.start()
    t.join(0.3)
    assert t.is_alive()  # blocked: frame 0 is still being encoded
    gate.set()
    t.join(10)
    assert not t.is_alive()
    w.put(frames[2])
    assert sorted(w.close()) == sorted(_serial_files(meta, frames))


def test_threaded_writer_raises_the_workers_error_with_its_message(tmp_path):
    meta = fake_meta(frames=3)
    frames = fake_frames(meta)
    bad = dict(frames[1], frame=0)  # a repeated frame index: encode_scene refuses it in the worker
    with pytest.raises(ValueError, match=r"frame index 0 is invalid or repeated"):
        with C.ThreadedSceneWriter(tmp_path, meta["scene_id"], fake_scene(), meta) as w:
            w.put(frames[0])
            w.put(bad)
            w.put(frames[2])  # the worker has failed by now at the latest: raised here or by close()
            w.close()
    assert not w.alive
    assert _no_tmp(tmp_path)


def test_threaded_writer_disk_full_is_a_corpus_write_error(tmp_path, monkeypatch):
    meta = fake_meta(frames=2)
    frames = fake_frames(meta)
    disk_full_after(monkeypatch, 3)
    with pytest.raises(C.CorpusWriteError, match="disk full") as ei:
        with C.ThreadedSceneWriter(tmp_path, meta["scene_id"], fake_scene(), meta) as w:
            for fr in frames:
                w.put(fr)
            w.close()
    assert ei.value.errno == errno.ENOSPC and not w.alive
    assert _no_tmp(tmp_path)


def test_threaded_writer_stops_on_an_interrupt_in_the_producer(tmp_path):
    """Ctrl-C (or any error) while the next frame renders: the worker stops at a file boundary and is joined;
    every file on disk is complete (temp name, then rename) and the later frames are never written."""
    meta = fake_meta(frames=3)
    frames = fake_frames(meta)
    want = _serial_files(meta, frames)

    def render():
        yield frames[0]
        raise KeyboardInterrupt
    with pytest.raises(KeyboardInterrupt):
        with C.ThreadedSceneWriter(tmp_path, meta["scene_id"], fake_scene(), meta) as w:
            for fr in render():
                w.put(fr)
            w.close()
    assert not w.alive
    assert _no_tmp(tmp_path)
    written = {p.relative_to(tmp_path).as_posix() for p in tmp_path.rglob("*") if p.is_file()}
    assert written <= set(want)
    assert not any("/f001/" in r or "/f002/" in r for r in written)
    for rel in written:
        assert (tmp_path / rel).read_bytes() == want[rel], rel  # no half-written file
    with pytest.raises(RuntimeError, match="aborted"):
        w.close()


def test_is_complete_checks_checksums(one_scene):
    root, meta, _ = one_scene
    w = C.CorpusWriter(root)
    assert w.is_complete(meta["scene_id"])
    p = root / "scenes" / meta["scene_id"] / "f001" / "aux.exr"
    b = bytearray(p.read_bytes())
    b[-5] ^= 0xFF
    p.write_bytes(bytes(b))
    assert not w.is_complete(meta["scene_id"])
    assert w.is_complete(meta["scene_id"], verify=False)


def test_rewrite_prunes_stale_files_and_render_record(tmp_path):
    meta = fake_meta()
    w = C.CorpusWriter(tmp_path, render={"seed": 1, "options": {"spp": 4}})
    w.write_scene(meta["scene_id"], fake_scene(), meta, fake_frames(meta))
    m2 = fake_meta(groups={"skymap": {"flicker": False}})
    w.write_scene(meta["scene_id"], fake_scene(), m2, fake_frames(m2, aux=False))
    w.write_splits(0)
    left = sorted(p.name for p in (tmp_path / "scenes" / meta["scene_id"] / "f000").iterdir())
    assert left == ["skymap.exr"]
    assert C.validate_corpus(tmp_path).ok
    with pytest.raises(ValueError, match="different options \\(options\\)"):
        C.CorpusWriter(tmp_path, render={"seed": 1, "options": {"spp": 8}})
    C.CorpusWriter(tmp_path, render={"seed": 1, "options": {"spp": 4}})


def test_atomic_write_permissions(tmp_path):
    digest = C.atomic_write_bytes(tmp_path / "a" / "b.bin", b"abc")
    assert digest == "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"  # FIPS 180-2 example
    mode = (tmp_path / "a" / "b.bin").stat().st_mode & 0o777
    um = os.umask(0)
    os.umask(um)
    assert mode == 0o666 & ~um


# ------------------------------------------------------------------------------------------------ splits
def test_splits_deterministic_and_disjoint():
    ids = [f"s{i:03d}" for i in range(10)]
    a = C.make_splits(ids, 3)
    assert a == C.make_splits(list(reversed(ids)), 3)
    assert [len(a[k]) for k in ("train", "val", "test")] == [6, 2, 2]
    assert sorted(a["train"] + a["val"] + a["test"]) == ids
    assert a != C.make_splits(ids, 4)
    assert C.make_splits(["only"], 0) == {"train": [], "val": [], "test": ["only"]}
    two = C.make_splits(["a", "b"], 0)
    assert len(two["test"]) == 1 and len(two["train"]) == 1 and two["val"] == []
    for n in range(1, 30):
        s = C.make_splits([str(i) for i in range(n)], n)
        assert len(s["test"]) >= 1 and sum(map(len, s.values())) == n
        if n >= 2:
            assert len(s["train"]) >= 1
    with pytest.raises(ValueError, match="fractions"):
        C.make_splits(ids, 0, (0.5, 0.5, 0.5))


def test_cleanup_temp_of_one_scene_leaves_the_others(tmp_path):
    """After a render worker dies, the driver removes that scene's temporary files only: another worker may be
    writing its own scene's at that moment."""
    w = C.CorpusWriter(tmp_path / "c")
    mine, other = (w.root / C.SCENES_DIR / s for s in ("scene00001", "scene00002"))
    for d in (mine, other):
        d.mkdir(parents=True)
        (d / (C.TMP_PREFIX + "frame0000.exr.x")).write_bytes(b"partial")
    (mine / "kept.txt").write_text("not ours to delete")
    assert w.cleanup_temp("scene00001") == 1
    assert sorted(p.name for p in mine.iterdir()) == ["kept.txt"]
    assert (other / (C.TMP_PREFIX + "frame0000.exr.x")).exists()
    with pytest.raises(ValueError, match="scene_id"):
        w.cleanup_temp("../x")
