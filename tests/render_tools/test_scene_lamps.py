"""Lamp clusters and LED displays of scene generator 2 (render_tools.lamps, render_tools.led_matrix): what the
generator writes, the geometry of LED dot faces, and one clear error per bad scene field."""
from __future__ import annotations

import collections
import copy
import json
import math

import numpy as np
import pytest

from lfmbench.flicker.waveforms import ScanRow, waveform_from_dict
from render_tools import led_matrix as LM
from render_tools import mitsuba_scene as MS
from render_tools import scene as S
from render_tools.lamp_closeup import closeup_scene, light_weights
from render_tools.scene_schema import KIND_WAVEFORMS, load_scene


@pytest.fixture(scope="module")
def v2_scenes():
    return [S.generate_scene(seed, time_of_day=("night", "dusk", "day")[seed % 3], generator=2) for seed in range(12)]


def test_generator_2_writes_the_new_light_kinds(v2_scenes):
    kinds = collections.Counter(lt["kind"] for sc in v2_scenes for lt in sc["lights"])
    for k in ("drl", "chmsl", "strobe", "message_sign", "countdown", "indicator", "tail", "brake", "headlight"):
        assert kinds[k] > 0, (k, kinds)
    for sc in v2_scenes:
        for lt in sc["lights"]:
            allowed = KIND_WAVEFORMS.get(lt["kind"], ("pwm",))
            kind = lt["waveform"]["kind"] if "waveform" in lt else allowed[0]
            assert kind in allowed and kind is not None
            waveform_from_dict(lt.get("waveform", {"kind": "pwm"}))


def test_v1_scenes_have_none_of_the_version_2_light_fields():
    sc = S.generate_scene(3, time_of_day="night")
    assert sc["version"] == 1
    assert all("waveform" not in lt and "driver" not in lt and lt["shape"] != "dots" for lt in sc["lights"])


def test_message_sign_lines_carry_the_text_and_their_scan_phase(v2_scenes):
    """Every message-sign light is one scan line of its sign: the dots of the text's rows that line drives (row
    mod scan_lines); the lines share one driver; together they are exactly the text's dots."""
    seen = 0
    for sc in v2_scenes:
        by_obj = collections.defaultdict(list)
        for lt in sc["lights"]:
            if lt["kind"] == "message_sign":
                by_obj[lt["instance"]].append(lt)
        for oid, rows in by_obj.items():
            disp = sc["objects"][oid]["display"]
            want = LM.text_cells(disp["texts"][0], disp["grid"])
            got = sorted((c for lt in rows for c in lt["cells"]), key=lambda cr: (cr[1], cr[0]))
            assert got == want
            assert len({lt["driver"] for lt in rows}) == 1
            for lt in rows:
                lines = {c[1] % disp["scan_lines"] for c in lt["cells"]}
                assert len(lines) == 1
                assert lt["waveform"] == {"kind": "scan_row", "scan_lines": disp["scan_lines"], "line": lines.pop()}
            assert len(rows) == len({c[1] % disp["scan_lines"] for c in want})
            seen += 1
    assert seen >= 2


def test_segments_share_one_light_unless_unsynchronised():
    """Synchronised: a segmented tail lamp is one light whose dots are its segments (one PWM); unsynchronised:
    one light per segment, each drawing its own PWM (no driver)."""
    base = {"time_of_day": "night", "generator": 2}
    sync = S.generate_scene(1, overrides={"lamps": {"unsynchronised_segments": 0.0, "tail_segments": [3, 3]}},
                            **base)
    free = S.generate_scene(1, overrides={"lamps": {"unsynchronised_segments": 1.0, "tail_segments": [3, 3]}},
                            **base)
    tails_s = [lt for lt in sync["lights"] if lt["kind"] == "tail" and lt["grid"] == [3, 1]]
    tails_f = [lt for lt in free["lights"] if lt["kind"] == "tail" and lt["grid"] == [3, 1]]
    assert tails_s and all(len(lt["cells"]) == 3 and lt["driver"].endswith(".tail") for lt in tails_s)
    assert len(tails_f) == 3 * len(tails_s)
    assert all(len(lt["cells"]) == 1 and "driver" not in lt for lt in tails_f)
    # same emitting area either way
    assert sum(MS.plane_area(lt) for lt in tails_f) == pytest.approx(sum(MS.plane_area(lt) for lt in tails_s))


def test_dots_face_geometry():
    """A sign facing -x (towards a camera at smaller x): column 0 at the viewer's left (+y), row 0 at the top;
    the mesh's triangles face along the normal and their area is the dots' area."""
    face = {"shape": "dots", "center": [10.0, 1.0, 2.0], "normal": [-1.0, 0.0, 0.0], "size": [1.2, 0.4],
            "grid": [12, 4], "dot": 0.5, "cells": [[0, 0], [11, 0], [0, 3], [5, 2]]}
    u, v, n = MS._frame(face["normal"])
    c = LM.dot_centers(face, u, v)
    assert c[0, 1] > c[1, 1] and c[0, 2] > c[2, 2]
    np.testing.assert_allclose(c[0], [10.0, 1.0 + 0.55, 2.0 + 0.15])
    V, F = MS._plane_mesh(face, np.zeros(3))
    tri = V[F]
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    np.testing.assert_allclose(cross / np.linalg.norm(cross, axis=1)[:, None], np.tile(n, (len(F), 1)), atol=1e-12)
    assert 0.5 * np.linalg.norm(cross, axis=1).sum() == pytest.approx(MS.plane_area(face)) == pytest.approx(
        4 * 0.05 * 0.05)
    assert MS.plane_corners(face).shape == (16, 3)


def test_led_array_signal_keeps_the_flux(v2_scenes):
    for sc in v2_scenes:
        for lt in sc["lights"]:
            if lt["kind"] == "signal":
                assert lt["shape"] == "dots"
                r = lt["size"][0] / 2
                # luminance x area = the disk's (the generator's signal luminance range)
                lum_disk = lt["luminance_cd_m2"] * MS.plane_area(lt) / (math.pi * r * r)
                assert 5e3 <= lum_disk <= 2e4


def test_countdown_segments_show_the_count(v2_scenes):
    """The countdown's lights are the bars that are ever lit, on one driver, with the countdown waveform."""
    found = False
    for sc in v2_scenes:
        cd = [lt for lt in sc["lights"] if lt["kind"] == "countdown"]
        if not cd:
            continue
        found = True
        wf = [waveform_from_dict(lt["waveform"]) for lt in cd]
        assert len({lt["driver"] for lt in cd}) == 1 and len({w.count_from for w in wf}) == 1
        assert all(w.gate()[1].shape[0] > 0 for w in wf)
        units = {w.segment for w in wf if w.place == "units"}
        assert units == set("abcdefg") if wf[0].count_from >= 8 else units
    assert found


def test_closeup_short_exposure_rows_differ():
    """The close-up: in a 1.2 ms exposure at 200 Hz with a 1/8 scan, some sign rows get light and some none,
    while the flicker-free exposure lights every row; the bin weights sum to the window's exposure."""
    sc = closeup_scene()
    edges = np.linspace(0.0, 0.016, 17)
    win = (0.003, 0.0042)
    carrier = {lt["id"]: (1 / 200.0, 0.9 if lt["kind"] == "message_sign" else 0.5, 0.001) for lt in sc["lights"]}
    short = light_weights(sc, edges, win, carrier, mean=False)
    mean = light_weights(sc, edges, win, carrier, mean=True)
    rows = [lt for lt in sc["lights"] if lt["kind"] == "message_sign"]
    lit = [short[lt["id"]].sum() for lt in rows]
    assert min(lit) == 0.0 and max(lit) > 0.0
    assert all(mean[lt["id"]].sum() == pytest.approx(0.9 / 8) for lt in rows)
    for lt in rows:
        w = ScanRow(**{k: v for k, v in lt["waveform"].items() if k != "kind"})
        assert short[lt["id"]].sum() * 0.0012 == pytest.approx(float(w.exposure(0.003, 0.0012, 1 / 200.0, 0.9,
                                                                                  0.001)))


# ------------------------------------------------------------------------------------------------ bad input
def _scene_with_sign():
    return copy.deepcopy(closeup_scene())


def _first(sc, kind):
    return next(i for i, lt in enumerate(sc["lights"]) if lt["kind"] == kind)


def _edit_unknown_kind(sc):
    sc["lights"][0]["kind"] = "laser"
    return "scene.lights[0].kind"


def _edit_text_too_long(sc):
    o = next(o for o in sc["objects"] if "display" in o)
    o["display"]["texts"] = ["ROAD WORKS AHEAD FOR THE NEXT 12 KM"]
    return f"scene.objects[{o['id']}].display.texts[0]' 'ROAD WORKS AHEAD FOR THE NEXT 12 KM' is too long"


def _edit_absurd_rows(sc):
    o = next(o for o in sc["objects"] if "display" in o)
    o["display"]["grid"] = [60, 10**6]
    return f"scene.objects[{o['id']}].display.grid[1]' must be an integer in [1, 256]"


def _edit_absurd_dot_rows(sc):
    i = _first(sc, "message_sign")
    sc["lights"][i]["grid"] = [60, 100000]
    return f"scene.lights[{i}].grid[1]' must be an integer in [1, 256]"


def _edit_dot_outside(sc):
    i = _first(sc, "message_sign")
    sc["lights"][i]["cells"].append([60, 0])
    return f"scene.lights[{i}].cells[{len(sc['lights'][i]['cells']) - 1}][0]'"


def _edit_missing_waveform(sc):
    i = _first(sc, "message_sign")
    del sc["lights"][i]["waveform"]
    return f"scene.lights[{i}].waveform' is missing"


def _edit_wrong_waveform(sc):
    i = _first(sc, "indicator")
    sc["lights"][i]["waveform"] = {"kind": "strobe"}
    return f"scene.lights[{i}].waveform.kind' 'strobe' is not a waveform of a indicator light"


def _edit_scan_lines(sc):
    i = _first(sc, "message_sign")
    sc["lights"][i]["waveform"]["scan_lines"] = 4096
    return f"scene.lights[{i}].waveform.scan_lines' must be an integer in [1, 64]"


def _edit_v1_with_waveform(sc):
    sc["version"] = 1
    del sc["weather"]
    for o in sc["objects"]:
        o.pop("display", None)
    return "needs scene version 2"


@pytest.mark.parametrize("edit", [_edit_unknown_kind, _edit_text_too_long, _edit_absurd_rows, _edit_absurd_dot_rows,
                                  _edit_dot_outside, _edit_missing_waveform, _edit_wrong_waveform, _edit_scan_lines,
                                  _edit_v1_with_waveform])
def test_bad_scene_fields_one_line_naming_file_and_field(tmp_path, edit):
    sc = _scene_with_sign()
    want = edit(sc)
    p = tmp_path / "bad.json"
    p.write_text(json.dumps(sc))
    with pytest.raises(ValueError) as err:
        load_scene(p)
    msg = str(err.value)
    assert msg.startswith(f"scene file {p}: ") and "\n" not in msg
    assert want in msg, msg


def test_text_on_the_font_and_grid():
    assert LM.text_columns("SLOW") == 23
    cells = LM.text_cells("I", (5, 7))
    assert sorted(cells) == sorted([[c, 0] for c in (1, 2, 3)] + [[2, r] for r in range(1, 6)] +
                                   [[c, 6] for c in (1, 2, 3)])
    with pytest.raises(ValueError, match="not in the 5x7 font"):
        LM.text_cells("slow", (60, 7))
    with pytest.raises(ValueError, match="needs 23 x 7 dots"):
        LM.text_cells("SLOW", (20, 7))
    assert len(LM.disk_cells(13)) < 13 * 13 and [6, 0] in LM.disk_cells(13) and [0, 0] not in LM.disk_cells(13)


# ------------------------------------------------------------------------------------------------ rendering
def _dots_scene(dot, cells, grid=(4, 4), size=(0.2, 0.2), center=(3.0, 0.0, 3.0), normal=(0, 0, -1)):
    from tests.data.render.data import HPS

    s = S.empty_scene(position_m=(3.0, 0.0, 2.0), pitch_deg=-89.0, fov_x_deg=4.0)
    s["version"] = 2
    s["materials"]["grey"] = {"type": "diffuse", "rgb": [0.5, 0.5, 0.5]}
    s["objects"].append({"id": 0, "kind": "ground", "velocity_mps": [0, 0, 0],
                         "parts": [{"shape": "rect", "center": [0, 0, 0], "size": [200, 200], "normal": [0, 0, 1],
                                    "material": "grey"}]})
    s["lights"].append({"id": 0, "group": "streetlights", "kind": "streetlight", "instance": -1, "shape": "dots",
                        "center": list(center), "normal": list(normal), "size": list(size), "grid": list(grid),
                        "dot": dot, "cells": cells, "spread_deg": 90.0, "spectrum": HPS, "luminance_cd_m2": 3e4})
    return S.validate_scene(s), HPS


@pytest.mark.jit
def test_dots_lamp_lights_a_plane_as_its_lit_area():
    """A 4 x 4 LED array (dot 0.5: a quarter of the face lit) 3 m above a grey plane: the plane's radiance is
    rho L A_dots / (pi h^2) (small Lambertian source), A_dots = 16 (0.5 x 0.05 m)^2 = 0.01 m^2."""
    from render_tools import render, spectra

    s, spec = _dots_scene(0.5, [[c, r] for r in range(4) for c in range(4)])
    assert MS.plane_area(s["lights"][0]) == pytest.approx(0.01)
    opts = render.RenderOptions(width=6, height=4, spp=64, frames=1, aux=False, static_denoise="off")  # the tracer
    img = next(render.render_frames(s, opts))["static"]["streetlights"]["short"]
    exp = 0.5 * spectra.band_means(spectra.absolute_spectrum(spec, 3e4), opts.bands_nm, opts.band_width_nm) \
        * 0.01 / (math.pi * 3.0 ** 2)
    assert np.allclose(img.mean((1, 2)), exp, rtol=0.04, atol=0.02 * exp.max())


@pytest.mark.jit
def test_directly_viewed_dots_face_has_its_luminance():
    """A camera looking straight up at a 2 x 2 m matrix of 8 x 8 dots that tile it (dot 1) filling its view: every
    pixel inside sees the face's luminance L (the dots' quads are one-sided emitters facing the camera)."""
    from render_tools import render, spectra

    cells = [[c, r] for r in range(8) for c in range(8)]
    s, spec = _dots_scene(1.0, cells, grid=(8, 8), size=(2.0, 2.0), center=(3.0, 0.0, 2.5))
    s["camera"].update({"position_m": [3.0, 0.0, 0.1], "pitch_deg": 89.0, "fov_x_deg": 60.0})
    s["objects"] = []
    s = S.validate_scene(s)
    opts = render.RenderOptions(width=64, height=36, spp=8, frames=1, aux=False, static_denoise="off")  # the tracer
    img = next(render.render_frames(s, opts))["static"]["streetlights"]["short"]
    L = spectra.band_means(spectra.absolute_spectrum(spec, 3e4), opts.bands_nm, opts.band_width_nm)
    mid = img[:, 6:30, 20:44]                       # well inside the face (it spans ~2.3 m at 2.4 m, 60 deg)
    peak = L > 0.2 * L.max()
    assert np.allclose(mid.mean((1, 2))[peak], L[peak], rtol=0.02)


def test_render_command_refuses_a_too_long_sign_text(tmp_path):
    """``lfmbench render --scene`` with a sign text that does not fit: exit 2, one line naming the file and the
    field, no traceback, nothing written."""
    from tests.data.render.data import ARGS, run

    sc = _scene_with_sign()
    _edit_text_too_long(sc)
    p = tmp_path / "sign.json"
    p.write_text(json.dumps(sc))
    out = tmp_path / "corpus"
    r = run("--out", str(out), "--scene", str(p), *ARGS)
    assert r.exit_code == 2, r.output
    assert f"--scene {p}: field 'scene.objects[" in r.output and "is too long for the sign" in r.output
    assert "Traceback" not in r.output and not out.exists()


def test_centre_brake_lamp_sits_on_the_body_under_the_roof_line():
    """Generator 2's centre high-mounted stop lamp (a body's ``chmsl``, else the template's ``cbrake``) has its top
    at least 1 cm under the roof line of its body (the highest loft station within 0.11 m of it) and lies on a body
    face: at most 1 cm behind the rear face of the rearmost loft station or of an extra box (a car's roof lip),
    which covers the lamp's whole width and height (it neither floats above the roof nor hangs in the air); the
    generated car's ``chmsl`` light is that lamp."""
    from render_tools.scene_templates import VEHICLE_BODIES, VEHICLE_TEMPLATES

    checked = 0
    for kind, t in VEHICLE_TEMPLATES.items():
        body = VEHICLE_BODIES.get(kind, {})
        place = body.get("chmsl", t["cbrake"])
        if place is None:
            continue
        cx, cy, cz, w, h = place
        st = np.asarray(body["stations"], dtype=float)
        roof = st[np.abs(st[:, 0] - cx) <= 0.11, 3].max()
        assert cz + h / 2 <= roof - 0.01, kind
        faces = [(st[0, 0], st[0, 1], st[0, 3], body["width"] * st[0, 4] / 2 - body["roof_inset"])]
        faces += [(bx - sx / 2, bz - sz / 2, bz + sz / 2, sy / 2) for (bx, by, bz), (sx, sy, sz), _ in body["boxes"]]
        on = [f for f in faces if -0.01 <= f[0] - cx <= 0.01 and f[1] <= cz - h / 2 and cz + h / 2 <= f[2]
              and abs(cy) + w / 2 <= f[3]]
        assert on, (kind, faces)
        checked += 1
    assert checked == 3  # car, van, bus
    sc = closeup_scene()  # a car with generator 2's lamps
    (chmsl,) = [lt for lt in sc["lights"] if lt["kind"] == "chmsl"]
    assert chmsl["center"][2] == pytest.approx(VEHICLE_BODIES["car"]["chmsl"][2])
