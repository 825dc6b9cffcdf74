"""Import of the released ISET-LFM dataset (lfmbench.corpus.isetlfm) from tiny files written in its layout."""
from __future__ import annotations

import json

import numpy as np
import OpenEXR
import pytest
import scipy.io
from typer.testing import CliRunner

from lfmbench import corpus as C
from lfmbench.corpus import isetlfm as I
from lfmbench.cli import app

H, W = 6, 10
WL = [400, 550, 700]


def _chan(wl):
    return f"S0.{wl},000nm"  # ISET3D / PBRT spectral channel name, e.g. S0.400,000nm


def _write_exr(path, rng, *, depth="P", instance=False, nan=False, dtype=np.float32):
    path.parent.mkdir(parents=True, exist_ok=True)
    ch = {_chan(wl): (3 * rng.random((H, W))).astype(dtype) for wl in WL}
    if nan:
        ch[_chan(550)][1, 1] = np.nan
    P = rng.normal(size=(3, H, W)).astype(np.float32)
    P[:, 0, 0] = 0.0  # no surface (sky)
    if depth == "P":
        ch.update({"P.X": P[0], "P.Y": P[1], "P.Z": P[2]})
    elif depth == "Pxyz":
        ch.update({"Px": P[0], "Py": P[1], "Pz": P[2]})
    if instance:
        ch["InstanceId"] = np.arange(H * W, dtype=np.float32).reshape(H, W) % 7
    OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage},
                 dict(ch)).write(str(path))  # (OpenEXR turns the dict values into Channel objects)
    return ch


def make_iset_scene(src, sid, groups=I.ISET_GROUPS, frames=3, mat=True, seed=0, sub="", **kw):
    """Write ``src/<sid>/<sid>_<group>/{lpd,spd}/[sub/]NN.exr`` (+ ``<sid>_lf.mat``); returns the channel dicts."""
    rng = np.random.default_rng(seed)
    out = {}
    for g in groups:
        for e in ("lpd", "spd"):
            for f in range(1, frames + 1):
                p = src / sid / f"{sid}_{g}" / e / sub / f"{f:02d}.exr"
                out[g, e, f] = _write_exr(p, rng, instance=(g == groups[0]), **kw)
    if mat:
        scipy.io.savemat(str(src / sid / f"{sid}_lf.mat"), {"sceneMeta": {
            "cameraSpeed": 33.5, "lpd_exposure": 0.0042, "spd_exposure": 0.0111, "fps": 60.0,
            "depthMap": np.full((H, W), 7.0), "instanceMap": np.ones((H, W))}})
    return out


def test_parse_band_channel():
    assert I.parse_band_channel("S0.400,000nm") == 400.0
    assert I.parse_band_channel("S0.402,500nm") == 402.5
    assert I.parse_band_channel("S0.700nm") == 700.0
    assert I.parse_band_channel("P.X") is None
    assert I.parse_band_channel("R") is None


def test_import_round_trip(tmp_path):
    src, out = tmp_path / "iset", tmp_path / "corpus"
    a = make_iset_scene(src, "1112201236")
    b = make_iset_scene(src, "1113042919", groups=("headlights", "otherlights"), frames=3, seed=1, sub="renderings")
    rep = I.import_isetlfm(src, out)
    assert rep.imported == ["1112201236", "1113042919"] and rep.repaired == {}
    c = C.Corpus(out)
    assert c.scenes == ["1112201236", "1113042919"]
    m = c.meta("1112201236")
    assert m["bands_nm"] == [400.0, 550.0, 700.0] and m["band_width_nm"] == 150.0
    assert (m["width"], m["height"], m["frames"]) == (W, H, 3)
    assert m["timing"]["short_exposure_s"] == 0.0042 and m["timing"]["long_exposure_s"] == 0.0111
    assert m["camera"]["speed_mps"] == 33.5
    assert m["groups"] == {"headlights": {"flicker": False}, "streetlights": {"flicker": False},
                           "otherlights": {"flicker": True, "bins": 0}, "skymap": {"flicker": False}}
    assert m["lights"] == []
    # camera moves along its view axis by v * t: capture-window start of frame 2 at t = 2/60 s
    pose = np.array(m["camera"]["poses"][2][0])
    np.testing.assert_allclose(pose[:3, 3], [33.5 * 2 / 60, 0, 0])
    np.testing.assert_allclose(pose[:3, :3] @ [0, 0, 1], [1, 0, 0])  # optical axis = world forward (+x)
    for g in I.ISET_GROUPS:
        for f in (1, 3):
            short = c.read_static("1112201236", f - 1, g, "short")
            long = c.read_static("1112201236", f - 1, g, "long")
            for i, wl in enumerate(WL):
                np.testing.assert_array_equal(short[i], a[g, "lpd", f][_chan(wl)])
                np.testing.assert_array_equal(long[i], a[g, "spd", f][_chan(wl)])
    with pytest.raises(ValueError, match="read_static"):
        c.read_light_bins("1112201236", 0, "otherlights")
    # depth: range |P|, z |P.Z|, +inf where P = 0; instance ids from InstanceId of the first group
    aux = c.read_aux("1112201236", 1)
    src0 = a["headlights", "lpd", 2]
    P = np.stack([src0["P.X"], src0["P.Y"], src0["P.Z"]])
    R = np.sqrt((P.astype(np.float64) ** 2).sum(0))
    assert np.isinf(aux["depth.R"][0, 0]) and np.isinf(aux["depth.Z"][0, 0])
    np.testing.assert_allclose(aux["depth.R"][1:], R[1:], rtol=1e-6)
    np.testing.assert_allclose(aux["depth.Z"][1:], np.abs(P[2][1:]), rtol=1e-6)
    np.testing.assert_array_equal(aux["mask.instance"], src0["InstanceId"])
    np.testing.assert_array_equal(aux["mask.light"], -1)
    assert set(c.meta("1113042919")["groups"]) == {"headlights", "otherlights"}  # absent groups left out
    assert not c.path("1113042919", 0, "skymap").exists()
    np.testing.assert_array_equal(c.read_static("1113042919", 2, "otherlights", "long")[0],
                                  b["otherlights", "spd", 3][_chan(400)])
    assert C.validate_corpus(out).ok
    splits = json.loads((out / "splits.json").read_text())
    assert sorted(sum(splits.values(), [])) == c.scenes and len(splits["test"]) == 1
    # resume: nothing re-imported
    rep2 = I.import_isetlfm(src, out)
    assert rep2.imported == [] and rep2.skipped == c.scenes


def test_import_writes_no_path_of_the_importing_machine(tmp_path):
    """The same download imported from two places gives byte-identical scene.json / meta.json (and hashes): the
    scene's folder is recorded relative to the dataset folder, not as an absolute path."""
    import shutil

    make_iset_scene(tmp_path / "a" / "iset", "1112201236", frames=2)
    shutil.copytree(tmp_path / "a" / "iset", tmp_path / "elsewhere" / "deeper" / "iset")
    for src, out in ((tmp_path / "a" / "iset", tmp_path / "c1"),
                     (tmp_path / "elsewhere" / "deeper" / "iset", tmp_path / "c2")):
        I.import_isetlfm(src, out)
    for f in ("scene.json", "meta.json"):
        one = (tmp_path / "c1" / "scenes" / "1112201236" / f).read_bytes()
        assert one == (tmp_path / "c2" / "scenes" / "1112201236" / f).read_bytes()
        assert str(tmp_path).encode() not in one
    assert json.loads((tmp_path / "c1" / "scenes" / "1112201236" / "scene.json").read_text())["dataset_dir"] \
        == "1112201236"


def test_defaults_without_mat_and_old_depth_names(tmp_path):
    src = tmp_path / "iset"
    make_iset_scene(src, "s1", groups=("skymap",), frames=2, mat=False, depth="Pxyz", dtype=np.float16)
    with pytest.warns(UserWarning, match="default exposures"):
        rep = I.import_isetlfm(src, tmp_path / "c")
    assert any("no <SceneID>_lf.mat" in w for w in rep.warnings)
    m = C.Corpus(tmp_path / "c").meta("s1")
    assert m["timing"]["short_exposure_s"] == I.ISET_DEFAULTS["lpd_exposure"]
    assert m["fps"] == 60.0 and m["camera"]["speed_mps"] is None
    aux = C.Corpus(tmp_path / "c").read_aux("s1", 0)
    assert np.isfinite(aux["depth.R"][1:]).all() and np.isinf(aux["depth.R"][0, 0])


def test_depth_from_mat_when_no_P(tmp_path):
    src = tmp_path / "iset"
    make_iset_scene(src, "s2", groups=("headlights",), frames=1, depth=None)
    I.import_isetlfm(src, tmp_path / "c")
    aux = C.Corpus(tmp_path / "c").read_aux("s2", 0)
    np.testing.assert_array_equal(aux["depth.Z"], 7.0)


def test_bad_source_values_and_repair(tmp_path):
    src = tmp_path / "iset"
    make_iset_scene(src, "s3", groups=("streetlights",), frames=1, nan=True)
    with pytest.raises(C.CorpusValueError, match="s3_streetlights/lpd/01.exr: 1 NaN"):
        I.import_isetlfm(src, tmp_path / "c")
    assert C.Corpus(tmp_path / "c").scenes == []  # nothing half-imported is recorded
    rep = I.import_isetlfm(src, tmp_path / "c", repair=True)
    assert sum(rep.repaired.values()) == 2  # lpd and spd file each had one NaN
    c = C.Corpus(tmp_path / "c")
    assert c.read_static("s3", 0, "streetlights", "short")[1, 1, 1] == 0.0
    assert C.validate_corpus(tmp_path / "c").ok


def test_inconsistent_layout_errors(tmp_path):
    src = tmp_path / "iset"
    make_iset_scene(src, "s4", groups=("headlights", "skymap"), frames=2)
    (src / "s4" / "s4_skymap" / "spd" / "02.exr").unlink()
    with pytest.raises(ValueError, match="s4_skymap/spd: frames \\[1\\] differ"):
        I.find_scenes(src)
    with pytest.raises(ValueError, match="src: .* does not exist"):
        I.find_scenes(tmp_path / "nope")
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(ValueError, match="no ISET-LFM scenes"):
        I.import_isetlfm(empty, tmp_path / "c")


def test_cli_import(tmp_path):
    src = tmp_path / "iset"
    make_iset_scene(src, "s5", groups=("headlights", "otherlights"), frames=2)
    r = CliRunner().invoke(app, ["import-isetlfm", str(src), str(tmp_path / "c"), "--seed", "3"])
    assert r.exit_code == 0, r.output
    assert "imported 1 scenes" in r.output
    r = CliRunner().invoke(app, ["validate", str(tmp_path / "c")])
    assert r.exit_code == 0, r.output
    r = CliRunner().invoke(app, ["import-isetlfm", str(tmp_path / "nope"), str(tmp_path / "c")])
    assert r.exit_code == 2 and "does not exist" in r.output


def test_cli_prints_each_import_warning_once(tmp_path):
    """A scene without its .mat: the defaults warning is printed once (Python's warning printed it a second time
    beside the report's line)."""
    import sys
    import warnings

    src = tmp_path / "iset"
    make_iset_scene(src, "s6", groups=("skymap",), frames=2, mat=False)
    with warnings.catch_warnings():  # as outside pytest: a warning is printed to stderr, where the CLI's output is
        warnings.simplefilter("default")
        warnings.showwarning = lambda m, c, f, n, file=None, line=None: sys.stderr.write(
            warnings.formatwarning(m, c, f, n, line))
        r = CliRunner().invoke(app, ["import-isetlfm", str(src), str(tmp_path / "c")])
    assert r.exit_code == 0, r.output
    out = " ".join(r.output.split())
    assert out.count("no <SceneID>_lf.mat") == 1, r.output
