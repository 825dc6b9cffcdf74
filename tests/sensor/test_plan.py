"""Capture plans in sensor presets (lfmbench.sensor.plan): schema, architecture registry, bad input."""
from __future__ import annotations

import copy

import pytest
import yaml

from lfmbench.sensor import PRESET_DIR, load_preset
from lfmbench.sensor.plan import ARCHITECTURES, exposure_groups, resolve_windows, windows_overlap


def _dict(name="ovt"):
    d = yaml.safe_load((PRESET_DIR / f"{name}.yaml").read_text())
    d["spectral"]["filters"] = str(load_preset(name).filters_path)
    return d


def _single(**cap):
    """A minimal single-exposure preset dict built from the ovt one (one photodiode, one capture)."""
    d = _dict()
    d["architecture"] = "single"
    d["photodiodes"] = {"pd": dict(d["photodiodes"]["lpd"])}
    c = dict(d["captures"]["lpd_lcg"], photodiode="pd", exposure=[[0.0, 0.002]])
    c.update(cap)
    d["captures"] = {"main": c}
    return d


def _write(tmp_path, d, name="bad.yaml"):
    f = tmp_path / name
    f.write_text(yaml.safe_dump(d, sort_keys=False))
    return f


def test_split_pixel_plan_of_the_shipped_presets():
    for name in ("ovt", "imx490"):
        p = load_preset(name)
        assert p.architecture == "split_pixel" and p.reference == "lpd_hcg"
        assert [p.captures[c].exposure for c in ("lpd_hcg", "lpd_lcg", "spd")] == ["short", "short", "long"]
        assert p.exposures == {"lpd_hcg": ("lpd_hcg", "lpd_lcg"), "spd": ("spd",)}


def test_split_pixel_yaml_without_plan_fields_is_the_same_preset(tmp_path):
    """Older preset files (no architecture, no exposure) keep their meaning: LPD short, SPD long."""
    d = _dict()
    d.pop("architecture")
    for c in d["captures"].values():
        c.pop("exposure")
    old = load_preset(_write(tmp_path, d, "old.yaml"))
    new = load_preset("ovt")
    assert old.captures == new.captures and old.photodiodes == new.photodiodes
    assert (old.architecture, old.reference) == (new.architecture, new.reference)


def test_resolve_windows_short_is_centred_in_long():
    tm = {"short_exposure_s": 0.004, "long_exposure_s": 0.011}
    assert resolve_windows("long", tm) == ((0.0, 0.011),)
    (a, n), = resolve_windows("short", tm)
    assert n == 0.004 and a == pytest.approx(0.0035, abs=1e-15)
    assert resolve_windows(((0.001, 0.002),), tm) == ((0.001, 0.002),)


def test_windows_overlap_rule():
    assert windows_overlap([(0.0, 1.0)], [(0.5, 1.0)])
    assert not windows_overlap([(0.0, 1.0)], [(1.0, 1.0)])          # touching ends share no time
    assert not windows_overlap([(0.0, 0.1), (0.2, 0.1)], [(0.1, 0.1)])


def test_exposure_groups_share_charge_only_for_same_photodiode_and_windows():
    p = load_preset("ovt")
    assert exposure_groups(p.captures) == {"lpd_hcg": ("lpd_hcg", "lpd_lcg"), "spd": ("spd",)}


def test_registry_names_every_architecture():
    assert list(ARCHITECTURES) == ["split_pixel", "lofic", "staggered", "chopped", "single", "multi_photodiode"]


def test_single_plan_loads(tmp_path):
    p = load_preset(_write(tmp_path, _single(), "single_ok.yaml"))
    assert p.architecture == "single" and p.reference == "main" and p.captures["main"].exposure == ((0.0, 0.002),)
    with pytest.raises(ValueError, match="split pixel"):
        p.sensitivity_ratio


@pytest.mark.parametrize("mutate, field", [
    # overlapping windows of one capture
    (lambda d: d.update(architecture="chopped") or d["captures"]["main"].update(
        exposure=[[0.0, 0.002], [0.001, 0.002]]), "captures.main.exposure[1]"),
    # unsorted windows
    (lambda d: d.update(architecture="chopped") or d["captures"]["main"].update(
        exposure=[[0.004, 0.001], [0.0, 0.001]]), "captures.main.exposure[1]"),
    # a window out of the frame
    (lambda d: d.update(frame_time_s=1 / 90) or d["captures"]["main"].update(exposure=[[0.010, 0.002]]),
     "captures.main.exposure[0]"),
    (lambda d: d["captures"]["main"].update(exposure=[[-0.001, 0.002]]), "captures.main.exposure[0][0]"),
    (lambda d: d["captures"]["main"].update(exposure=[[0.0, 0.0]]), "captures.main.exposure[0][1]"),
    (lambda d: d["captures"]["main"].update(exposure="middle"), "captures.main.exposure"),
    (lambda d: d["captures"]["main"].update(exposure=[0.0, 0.1]), "captures.main.exposure[0]"),
    # unknown fields, at every level
    (lambda d: d["captures"]["main"].update(exposure_ms=3), "captures.main.exposure_ms"),
    (lambda d: d.update(plan=1), "plan"),
    (lambda d: d["captures"]["main"].update(readout={"shutter": "global", "mode": 2}), "captures.main.readout.mode"),
    (lambda d: d["captures"]["main"].update(readout={"shutter": "electronic"}), "captures.main.readout.shutter"),
    (lambda d: d.update(readout={"line_time_s": -1}), "readout.line_time_s"),
    # registry and structure
    (lambda d: d.update(architecture="quantum"), "architecture"),
    (lambda d: d.update(architecture="lofic"), "captures"),
    (lambda d: d.update(architecture="split_pixel"), "photodiodes.pd"),
    (lambda d: d["captures"]["main"].update(photodiode="lpd"), "captures.main.photodiode"),
    (lambda d: d["captures"].update(gt=d["captures"].pop("main")), "captures.gt"),
    (lambda d: d.update(reference="nope"), "reference"),
    (lambda d: d["captures"]["main"].pop("exposure"), "captures.main.exposure"),
])
def test_bad_plans_name_the_file_and_field(tmp_path, mutate, field):
    d = _single()
    mutate(d)
    with pytest.raises(ValueError) as exc:
        load_preset(_write(tmp_path, d))
    msg = str(exc.value)
    assert "bad.yaml" in msg and f"'{field}'" in msg and "\n" not in msg, msg


def test_overlapping_integrations_of_one_photodiode_are_refused(tmp_path):
    d = _single()
    d["architecture"] = "staggered"
    c = d["captures"]["main"]
    d["captures"] = {"long": dict(c, exposure=[[0.0, 0.010]]), "short": dict(c, exposure=[[0.009, 0.001]])}
    with pytest.raises(ValueError, match=r"bad\.yaml: field 'captures\.short\.exposure' overlaps"):
        load_preset(_write(tmp_path, d))
    d["captures"]["short"]["exposure"] = [[0.010, 0.001]]
    assert load_preset(_write(tmp_path, d, "ok.yaml")).architecture == "staggered"


def test_staggered_needs_longest_first_and_lofic_hcg_first(tmp_path):
    d = _single()
    d["architecture"] = "staggered"
    c = d["captures"]["main"]
    d["captures"] = {"a": dict(c, exposure=[[0.0, 0.001]]), "b": dict(c, exposure=[[0.001, 0.005]])}
    with pytest.raises(ValueError, match="longest exposure first"):
        load_preset(_write(tmp_path, d))
    e = _single()
    e["architecture"] = "lofic"
    c = e["captures"]["main"]
    e["captures"] = {"lcg": dict(c), "hcg": dict(c, conversion_gain_v_per_e=4 * c["conversion_gain_v_per_e"])}
    with pytest.raises(ValueError, match="high-conversion-gain"):
        load_preset(_write(tmp_path, e, "bad2.yaml"))
    e["captures"] = dict(reversed(list(e["captures"].items())))
    assert load_preset(_write(tmp_path, copy.deepcopy(e), "ok2.yaml")).exposures == {"hcg": ("hcg", "lcg")}


def test_generic_registry_holds_architectures_and_presets():
    from lfmbench.registry import Registry
    from lfmbench.sensor.plan import ARCHITECTURE_REGISTRY
    from lfmbench.sensor.preset import available_presets, preset_registry

    assert isinstance(ARCHITECTURE_REGISTRY, Registry) and list(ARCHITECTURE_REGISTRY.names()) == list(ARCHITECTURES)
    reg = preset_registry()
    assert list(reg.names()) == available_presets() and "imx490_4read" in reg and reg.get("ovt").name == "ovt.yaml"
    with pytest.raises(ValueError, match=r"unknown sensor preset 'nope'; valid: ar0132at, "):
        reg.get("nope")
    r = Registry("thing")
    r.register("a", 1)

    @r.register("b")
    def b():
        return 2

    assert r.get("b") is b and list(r) == ["a", "b"] and "a" in r
    with pytest.raises(ValueError, match="registered already"):
        r.register("a", 3)
