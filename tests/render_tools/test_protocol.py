"""Benchmark protocols (render_tools.protocol, ``lfmbench render --protocol``, ``lfmbench protocols``): the shipped
files load and cover what they promise, bad files give one clear error naming the file, the pinned conditions
hold in the generated scenes, and a tiny protocol renders end to end with the fake renderer."""
from __future__ import annotations

import copy
import json
import signal

import pytest
from typer.testing import CliRunner

from lfmbench import corpus as C
from lfmbench.cli import app
from lfmbench.datasets.pwm import TEST_SPLIT_SEED, load_pwm_config
from render_tools import protocol as P
from render_tools import scene as S

from tests.data.protocol.data import tiny_protocol_dict, write_protocol
from tests.data.render.data import FAIL, mitsuba_sigint

SHIPPED = ("lfmbench-v1", "lfmbench-v1-mini", "lfmbench-v1-mini-motion", "lfmbench-v2", "lfmbench-v2-mini")


@pytest.fixture(scope="module")
def cfg():
    return S.load_config()


# ------------------------------------------------------------------------------------------ shipped files
def test_shipped_protocols_listed():
    assert set(SHIPPED) <= set(P.list_protocols())


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_protocol_coverage(name):
    """The issue's rules, asserted from the file: >= 24 test scenes over day, dusk and night, every vehicle
    kind, signals in every state, a range of ego speeds; splits disjoint; the frozen PWM draws pinned."""
    p = P.load_protocol(name)
    assert p.name == name and p.version >= 1 and len(p.sha256) == 64
    cov = P.coverage(p, "test")
    assert cov["scenes"] >= 24
    assert all(cov["time_of_day"][t] >= 4 for t in ("day", "dusk", "night")), cov
    assert all(cov["vehicle_kinds"][k] >= 4 for k in ("car", "truck", "motorcycle")), cov
    assert all(cov["signal"][s] >= 1 for s in ("red", "amber", "green", "red_amber")), cov
    assert cov["scenes"] - cov["signal"]["none"] >= 0.75 * cov["scenes"]  # most test scenes have a signal
    lo, hi = cov["speed_range_mps"]
    assert lo <= 15 and hi >= 45 and all(n >= 3 for n in cov["ego_speed_mps"].values()), cov
    sp = p.splits
    ids = sp["train"] + sp["val"] + sp["test"]
    assert len(ids) == len(set(ids)) == len(p.scenes) and sp["train"] and sp["val"]
    assert len({s.seed for s in p.scenes}) == len(p.scenes)
    assert p.pwm["test_split_seed"] == TEST_SPLIT_SEED  # bump the protocol version when these change
    assert p.pwm["distributions"] == load_pwm_config().to_dict()
    # frozen_test_rng keys on the first 8 bytes of a scene id: every test id must differ there
    assert len({s.encode()[:8] for s in sp["test"]}) == len(sp["test"])


def test_mini_test_split_is_v1_subset():
    """The mini protocol renders v1's first 24 test scenes (same ids, seeds, conditions) at a smaller size,
    and its train / val scenes are v1's first ones."""
    v1, mini = P.load_protocol("lfmbench-v1"), P.load_protocol("lfmbench-v1-mini")
    for split in P.SPLITS:
        a = [s for s in v1.scenes if s.split == split]
        b = [s for s in mini.scenes if s.split == split]
        assert b == a[:len(b)]
    assert mini.render["width"] * mini.render["height"] < v1.render["width"] * v1.render["height"]
    assert mini.sha256 != v1.sha256


def test_mini_motion_is_mini_with_static_edges():
    """lfmbench-v1-mini-motion (version 2) is lfmbench-v1-mini (scenes, storage, PWM draws, every render setting)
    plus static time bins whose edges make every explicit window of the comparison's presets a union of bins, and
    the static window layer ``chopped`` whose windows are exactly the chopped preset's sub-windows: every capture's
    static radiance is exact (lfmbench.datasets.plan_frames.exposure_static_exact), chopped's through the layer
    alone; v1-mini itself has neither."""
    from lfmbench.datasets.plan_frames import exposure_static_exact, exposure_static_layer
    from lfmbench.sensor.preset import load_preset
    from lfmbench.sensor.plan import resolve_windows

    mini, mm = P.load_protocol("lfmbench-v1-mini"), P.load_protocol("lfmbench-v1-mini-motion")
    assert mm.version == 2
    assert mm.scenes == mini.scenes and mm.storage == mini.storage and mm.pwm == mini.pwm
    assert {k: v for k, v in mm.render.items() if k not in ("static_edges_s", "static_layers")} == mini.render
    assert "static_edges_s" not in mini.render and "static_layers" not in mini.render and mm.sha256 != mini.sha256
    tl, ts = 1.0 / 90.0, 0.004  # the renderer's T_L; a short window (its ends are edges whatever its length)
    edges = sorted({0.0, (tl - ts) / 2, (tl + ts) / 2, tl, *mm.render["static_edges_s"]})
    layers = [dict(x, moves=True) for x in mm.render["static_layers"]]
    for with_layers in (False, True):
        timing = {"short_exposure_s": ts, "long_exposure_s": tl, "static_edges_s": edges,
                  **({"window_layers": layers} if with_layers else {})}
        for name in ("ovt", "lofic", "staggered", "single", "imx490_4read", "ox03c10", "ar0132at", "mt9v024",
                     "lofic_akahane2006", "chopped"):
            pre = load_preset(name)
            exact = [exposure_static_exact(resolve_windows(c.exposure, timing), timing) for c in pre.captures.values()]
            assert all(exact) == (name != "chopped" or with_layers), (name, exact, with_layers)
            if name == "chopped" and with_layers:
                assert exposure_static_layer(resolve_windows(pre.captures["chopped"].exposure, timing),
                                             timing) == ("chopped", True)


def _entries(names, splits):
    out = {}
    for n in names:
        for s in P.load_protocol(n).scenes:
            if s.split in splits:
                out[(s.scene_id, s.seed)] = s
    return list(out.values())


@pytest.mark.parametrize("part", ["test", "mini-train-val"])
def test_pinned_conditions_hold(part, cfg):
    """Every test scene of the shipped protocols (and the mini's train / val scenes), generated from its seed
    and pins, meets every pinned condition (no rendering)."""
    entries = _entries(SHIPPED, ("test",)) if part == "test" else \
        _entries(("lfmbench-v1-mini", "lfmbench-v2-mini"), ("train", "val"))
    assert len(entries) >= 24
    cfgs = {1: cfg, 2: S.load_config(generator=2)}
    for ps in entries:
        c = cfgs[ps.generator]
        sc = S.generate_scene(ps.seed, scene_id=ps.scene_id, config=c, **ps.scene_kw())
        assert P.check_scene(sc, ps, c) == [], ps.scene_id


def test_check_scene_sees_a_missed_pin(cfg):
    ps = P.ProtocolScene("x", "test", 5, "night", 33.0, ("motorcycle",), "red_amber")
    sc = S.generate_scene(5, "day", config=cfg)  # no pins: drawn speed, kinds, signal
    bad = " ".join(P.check_scene(sc, ps))
    assert "time_of_day day != night" in bad and "ego speed" in bad
    sc = S.generate_scene(5, scene_id="x", config=cfg, **ps.scene_kw())
    assert P.check_scene(sc, ps) == []
    assert P.check_scene(sc, P.ProtocolScene("x", "test", 5, "night", 33.0, ("motorcycle",), "green"))


# ------------------------------------------------------------------------------------- override mechanism
def test_overrides_pin_the_condition(cfg):
    ov = {"camera": {"speed_mps": [33.0, 33.0]}, "vehicles": {"require_kinds": ["motorcycle", "truck"]},
          "lights": {"signal_states": ["amber"]}}
    for seed in (1, 2, 3):
        sc = S.generate_scene(seed, "dusk", config=cfg, overrides=ov)
        assert sc["camera"]["speed_mps"] == 33.0
        moving = [o["kind"] for o in sc["objects"] if any(o["velocity_mps"])]
        assert {"motorcycle", "truck"} <= set(moving)
        sig = [lt for lt in sc["lights"] if lt["kind"] == "signal"]
        assert sig and all(lt["spectrum"] == cfg["lights"]["led_amber"] for lt in sig)
    sc = S.generate_scene(1, "night", config=cfg, overrides={"lights": {"signal_states": []}})
    assert not [lt for lt in sc["lights"] if lt["group"] == "signals"]
    assert not [o for o in sc["objects"] if o["kind"] == "signal_pole"]


def test_default_overrides_change_nothing(cfg):
    """Overrides equal to the defaults give the same scene as none: the random stream is unchanged."""
    same = {"lights": {"signal_states": list(S.SIGNAL_STATES)}, "vehicles": {"require_kinds": []},
            "camera": {"speed_mps": list(cfg["camera"]["speed_mps"])}}
    assert S.generate_scene(4, "night", config=cfg, overrides=same) == S.generate_scene(4, "night", config=cfg)
    assert S.generate_scene(4, "night", config=cfg, overrides={"camera": {"speed_mps": [21.0, 21.0]}}) != \
        S.generate_scene(4, "night", config=cfg)


@pytest.mark.parametrize("ov, msg", [
    ({"camera": {"sped_mps": [1, 1]}}, "unknown key 'camera.sped_mps'"),
    ({"vehicles": {"require_kinds": ["tram"]}}, "vehicles.require_kinds"),
    ({"lights": {"signal_states": ["blue"]}}, "lights.signal_states"),
    ({"camera": {"speed_mps": [30, 20]}}, "camera.speed_mps"),
    ({"camera": 3}, "camera must be a mapping"),
])
def test_bad_overrides(ov, msg, cfg):
    with pytest.raises(ValueError, match=msg.replace(".", r"\.")):
        S.generate_scene(1, config=cfg, overrides=ov)


# ------------------------------------------------------------------------------------------ bad files
def _set(d, path, value):
    *head, last = path
    for k in head:
        d = d[k]
    if value is _DEL:
        del d[last]
    else:
        d[last] = value


_DEL = object()


@pytest.mark.parametrize("path, value, field", [
    (("format",), "lfmbench-protokoll", "format"),
    (("surprise",), 1, "surprise"),
    (("version",), 0, "version"),
    (("scenes", "test"), _DEL, "scenes.test"),
    (("scenes", "test", 0, "time_of_day"), "noon", "scenes.test[0].time_of_day"),
    (("scenes", "test", 0, "vehicle_kinds"), ["tram"], "scenes.test[0].vehicle_kinds"),
    (("scenes", "test", 0, "signal"), "blue", "scenes.test[0].signal"),
    (("scenes", "test", 0, "ego_speed_mps"), -1, "scenes.test[0].ego_speed_mps"),
    (("scenes", "test", 0, "id"), "tr_a", "appears twice"),
    (("scenes", "test", 0, "seed"), 11, "seed 11"),
    (("scenes", "test", 0, "overrides"), {"camera": {"speed_mps": [1, 1]}}, "must not set camera.speed_mps"),
    (("scenes", "test", 0, "overrides"), {"camera": {"fov": 30}}, "unknown key 'camera.fov'"),
    (("render", "width"), 0, "render"),
    (("render", "seed"), 3, "render.seed"),
    (("storage",), "jpeg", "storage"),
    (("coverage", "test", "min_scenes"), 2, "coverage.test.min_scenes"),
    (("coverage", "test", "times_of_day"), ["day"], "coverage.test.times_of_day"),
    (("coverage", "test", "ego_speed_range_mps"), [10, 50], "coverage.test.ego_speed_range_mps"),
])
def test_malformed_protocol(tmp_path, path, value, field):
    d = tiny_protocol_dict()
    _set(d, path, value)
    p = write_protocol(tmp_path / "bad.yaml", d)
    with pytest.raises(ValueError) as ei:
        P.load_protocol(p)
    msg = str(ei.value)
    assert msg.startswith(f"protocol file {p}") and field in msg and "\n" not in msg, msg


def test_unreadable_and_unknown_protocol(tmp_path):
    p = tmp_path / "broken.yaml"
    p.write_text("name: [unclosed\n")
    with pytest.raises(ValueError, match=f"protocol file {p}: cannot read YAML"):
        P.load_protocol(p)
    with pytest.raises(ValueError, match="'no-such-protocol' is neither"):
        P.load_protocol("no-such-protocol")


def test_hash_ignores_comments_not_values(tmp_path):
    p = write_protocol(tmp_path / "a.yaml")
    h = P.load_protocol(p).sha256
    p.write_text("# a comment\n" + p.read_text())
    assert P.load_protocol(p).sha256 == h
    d = tiny_protocol_dict()
    d["scenes"]["train"][0]["ego_speed_mps"] = 31
    assert P.load_protocol(write_protocol(tmp_path / "b.yaml", d)).sha256 != h


# ------------------------------------------------------------------------------------------ end to end
def _run(*args):
    return CliRunner().invoke(app, list(args))


def test_render_tiny_protocol(tmp_path, fake):
    proto = write_protocol(tmp_path / "tiny.yaml")
    p = P.load_protocol(proto)
    out = tmp_path / "c"
    r = _run("render", "--protocol", str(proto), "--out", str(out))
    assert r.exit_code == 0, r.output
    assert sorted(fake) == ["te_a", "tr_a", "va_a"]
    rep = C.validate_corpus(out)
    assert rep.ok, rep.errors
    c = C.Corpus(out)
    assert c.splits == {"train": ["tr_a"], "val": ["va_a"], "test": ["te_a"]}
    man = json.loads((out / "manifest.json").read_text())
    assert man["render"]["protocol"] == {"name": "tiny", "version": 1, "sha256": p.sha256}
    assert man["render"]["options"] == p.render and man["render"]["dtype"] == "compact"
    m = c.meta("te_a")
    assert m["protocol"] == {"name": "tiny", "version": 1, "sha256": p.sha256, "split": "test"}
    assert (m["width"], m["height"], m["frames"], m["timing"]["bins"]) == (24, 16, 2, 2)
    sc = c.scene("te_a")
    assert sc["seed"] == 13 and sc["time_of_day"] == "night" and sc["camera"]["speed_mps"] == 12.0
    assert P.check_scene(sc, next(s for s in p.scenes if s.scene_id == "te_a")) == []
    # same command: resumes (everything skipped); --variant is allowed, it changes speed, not radiance
    r = _run("render", "--protocol", str(proto), "--out", str(out), "--variant", "scalar_spectral")
    assert r.exit_code == 0 and "3 skipped" in r.output, r.output
    assert len(fake) == 3
    # another protocol (any changed value) into the same corpus: refused by the manifest's render record
    d = tiny_protocol_dict()
    d["version"] = 2
    r = _run("render", "--protocol", str(write_protocol(tmp_path / "tiny2.yaml", d)), "--out", str(out))
    assert r.exit_code == 2 and "rendered with different options (protocol)" in r.output, r.output


@pytest.mark.parametrize("extra", [["--width", "32"], ["--scenes", "5"], ["--seed", "1"], ["--profile", "small"],
                                   ["--storage", "float32"], ["--half"], ["--groups", "signals"]])
def test_protocol_refuses_contradicting_options(tmp_path, fake, extra):
    r = _run("render", "--protocol", "lfmbench-v1-mini", "--out", str(tmp_path / "c"), *extra)
    assert r.exit_code == 2 and f"{extra[0]} cannot be combined with --protocol" in r.output, r.output
    assert not (tmp_path / "c").exists() and fake == []


def test_failed_scene_left_out_of_splits(tmp_path, fake):
    """A scene that fails is in neither the manifest nor splits.json; re-running completes the protocol."""
    proto = write_protocol(tmp_path / "tiny.yaml")
    out = tmp_path / "c"
    FAIL["va_a"] = RuntimeError
    r = _run("render", "--protocol", str(proto), "--out", str(out))
    assert r.exit_code == 1
    assert C.Corpus(out).splits == {"train": ["tr_a"], "val": [], "test": ["te_a"]}
    assert C.validate_corpus(out).ok
    FAIL.clear()
    r = _run("render", "--protocol", str(proto), "--out", str(out))
    assert r.exit_code == 0 and "1 rendered" in r.output and "2 skipped" in r.output, r.output
    assert C.Corpus(out).splits["val"] == ["va_a"]


def test_protocols_command(tmp_path):
    r = _run("protocols")
    assert r.exit_code == 0 and all(n in r.output for n in SHIPPED), r.output
    proto = write_protocol(tmp_path / "tiny.yaml")
    r = _run("protocols", str(proto), "--check")
    assert r.exit_code == 0 and "3 of 3 scenes meet their pinned conditions" in r.output, r.output
    assert "| time of day | day 0, dusk 0, night 1 |" in r.output
    d = copy.deepcopy(tiny_protocol_dict())
    d["scenes"]["test"][0]["signal"] = "purple"
    r = _run("protocols", str(write_protocol(tmp_path / "bad.yaml", d)))
    assert r.exit_code == 2 and str(tmp_path / "bad.yaml") in r.output and "signal" in r.output
    # a generator-2 protocol: checked with generator 2's defaults, its weather pinned
    d2 = copy.deepcopy(tiny_protocol_dict())
    d2["generator"] = 2
    for split in d2["scenes"].values():
        for e in split:
            e["weather"] = "rain"
    r = _run("protocols", str(write_protocol(tmp_path / "v2.yaml", d2)), "--check")
    assert r.exit_code == 0 and "3 of 3 scenes meet their pinned conditions" in r.output, r.output
    assert "| weather | dry 0, wet 0, rain 1 |" in r.output
    del d2["scenes"]["test"][0]["weather"]
    r = _run("protocols", str(write_protocol(tmp_path / "v2bad.yaml", d2)))
    assert r.exit_code == 2 and "weather" in r.output


def test_render_protocol_one_split_then_the_rest(tmp_path, fake):
    """``--split test`` renders only the test scenes (splits.json lists only them); the same command without
    ``--split`` adds the others and skips the test scene; a misspelt split or ``--split`` without a protocol is
    refused before anything is written."""
    proto = write_protocol(tmp_path / "tiny.yaml")
    out = tmp_path / "c"
    r = _run("render", "--protocol", str(proto), "--out", str(out), "--split", "test")
    assert r.exit_code == 0 and "1 rendered" in r.output, r.output
    assert sorted(fake) == ["te_a"]
    assert C.Corpus(out).splits == {"train": [], "val": [], "test": ["te_a"]}
    r = _run("render", "--protocol", str(proto), "--out", str(out), "--split", "train,val")
    assert r.exit_code == 0 and "2 rendered" in r.output and "0 skipped" in r.output, r.output
    r = _run("render", "--protocol", str(proto), "--out", str(out))
    assert r.exit_code == 0 and "3 skipped" in r.output, r.output
    assert sorted(fake) == ["te_a", "tr_a", "va_a"]
    assert C.Corpus(out).splits == {"train": ["tr_a"], "val": ["va_a"], "test": ["te_a"]}
    r = _run("render", "--protocol", str(proto), "--out", str(tmp_path / "d"), "--split", "tset")
    assert r.exit_code == 2 and "--split 'tset' is not a split" in r.output, r.output
    r = _run("render", "--out", str(tmp_path / "d"), "--split", "test")
    assert r.exit_code == 2 and "--split needs --protocol" in r.output, r.output
    assert not (tmp_path / "d").exists()



def test_add_layers_upgrades_a_corpus_without_touching_its_files(tmp_path, fake):
    """A corpus of version 1 of a protocol gets version 2's static window layer (render.static_layers) by
    ``--add-layers``: only the layers are rendered, no file it had changes, the manifest then records version 2 (a
    resume with it skips every scene), and a fresh version-2 render writes the same set of files; Ctrl-C while a
    version 3 adds a layer stops as a render stops, and the rerun uses ``--workers``."""
    from tests.data.render.data import LAYER_CALLS

    out = tmp_path / "c"
    assert _run("render", "--protocol", str(write_protocol(tmp_path / "v1.yaml")), "--out", str(out)).exit_code == 0
    before = {p: (p.stat().st_mtime_ns, p.read_bytes()) for p in (out / "scenes").rglob("*") if p.is_file()}
    d = tiny_protocol_dict()
    d["version"] = 2
    d["render"]["static_layers"] = [{"name": "chopped", "windows_s": [[0.0, 0.0001], [0.00092, 0.0001]]}]
    v2 = write_protocol(tmp_path / "v2.yaml", d)
    bad = tiny_protocol_dict()
    bad["version"], bad["render"]["spp"] = 2, 4
    LAYER_CALLS.clear()
    r = _run("render", "--protocol", str(write_protocol(tmp_path / "bad.yaml", bad)), "--out", str(out),
             "--add-layers")
    assert r.exit_code == 2 and "other settings than" in r.output and "spp" in r.output, r.output
    assert not LAYER_CALLS and not list(out.rglob("*.layer_*"))
    r = _run("render", "--protocol", str(v2), "--out", str(out), "--add-layers")
    assert r.exit_code == 0 and "3 scene(s) got static window layers" in r.output, r.output
    assert sorted(LAYER_CALLS) == [("te_a", "chopped"), ("tr_a", "chopped"), ("va_a", "chopped")]
    assert {p: (p.stat().st_mtime_ns, p.read_bytes()) for p in before} == before
    assert C.validate_corpus(out).ok
    man = json.loads((out / "manifest.json").read_text())
    assert man["render"]["protocol"]["version"] == 2
    layer_files = sorted(p.relative_to(out).as_posix() for p in out.rglob("*.layer_chopped.exr"))
    assert layer_files and all(f in man["files"] for f in layer_files)
    assert C.Corpus(out).meta("te_a")["timing"]["window_layers"][0]["name"] == "chopped"
    r = _run("render", "--protocol", str(v2), "--out", str(out))
    assert r.exit_code == 0 and "3 skipped" in r.output, r.output
    r = _run("render", "--protocol", str(v2), "--out", str(out), "--add-layers")   # nothing missing: no render
    assert r.exit_code == 0 and "0 scene(s)" in r.output and len(LAYER_CALLS) == 3, r.output
    fresh = tmp_path / "fresh"
    assert _run("render", "--protocol", str(v2), "--out", str(fresh)).exit_code == 0
    assert sorted(p.relative_to(fresh).as_posix() for p in fresh.rglob("*.layer_chopped.exr")) == layer_files
    # version 3 adds a layer. Ctrl-C inside a scene's layer render (Mitsuba reports it as a RuntimeError) ends
    # --add-layers as it ends a render: exit 130 and a message, no traceback, the scenes before it committed, the
    # version not recorded; the rerun adds the rest and hands --workers to the process pool
    from render_tools import jobs as J

    d["version"] = 3
    d["render"]["static_layers"].append({"name": "second", "windows_s": [[0.0, 0.0001]]})
    v3 = write_protocol(tmp_path / "v3.yaml", d)
    first, second = C.Corpus(out).scenes[:2]
    n0 = len(LAYER_CALLS)
    FAIL[second] = mitsuba_sigint
    prev = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        r = _run("render", "--protocol", str(v3), "--out", str(out), "--add-layers")
    finally:
        signal.signal(signal.SIGINT, prev)
        FAIL.clear()
    assert r.exit_code == 130 and "interrupted: 1 scene(s)" in r.output and "Traceback" not in r.output, r.output
    assert [c[0] for c in LAYER_CALLS[n0:]] == [first, second]  # no further scene started
    man = json.loads((out / "manifest.json").read_text())
    assert man["render"]["protocol"]["version"] == 2 and C.validate_corpus(out).ok
    assert {f.split("/")[1] for f in man["files"] if f.endswith(".layer_second.exr")} == {first}
    assert not list(out.rglob(C.TMP_PREFIX + "*"))  # nothing half-written left behind
    pool = []

    def serial_pool(tasks, fn, workers, finished, label=str):  # run_supervised's contract, in this process
        pool.append(workers)
        for t in tasks:
            finished(t, fn(t), None)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(J, "run_supervised", serial_pool)
        r = _run("render", "--protocol", str(v3), "--out", str(out), "--add-layers", "--workers", "2")
    assert r.exit_code == 0 and "2 scene(s) got static window layers" in r.output, r.output
    assert pool == [2] and sorted(c[0] for c in LAYER_CALLS[n0 + 2:]) == sorted(set(C.Corpus(out).scenes) - {first})
    assert json.loads((out / "manifest.json").read_text())["render"]["protocol"]["version"] == 3

