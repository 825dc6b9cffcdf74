"""The two scene files of the ISET-LFM paper figures (``lfmbench/configs/paper_figures/*.json``) and how they
were made.

The scene files are the data of record (plain JSON of :mod:`render_tools.scene`, edit them by hand if you
like); this module only documents and reproduces their construction: a night street from the procedural
generator (``generate_scene(seed, "night")`` with no random vehicles), then vehicles placed by hand.
``python -m lfmbench.paper.scenes [OUT_DIR]`` rewrites them (default: the package's ``configs/paper_figures``).

- ``paper_fig4_6``: Figs. 4-6 of the paper (60 fps, ego speed 60 m/s, global shutter, LPD 5 ms, SPD 11.11 ms).
  Every vehicle is parked (velocity 0), as in the paper's model (a static environment, fast ego motion), with
  tail and brake lights on: a braking car in the ego lane 11 m ahead (the dropout), a braking motorcycle in
  the right lane 9 m ahead near the image edge (its small lamps sweep about twice their own width in 11.1 ms:
  the comet), two cars further ahead in the right lane and an oncoming car (headlights).
- ``paper_fig7``: Fig. 7 (a static scene, speed 0): a motorcycle coming towards the camera (its headlight and
  nothing else shows at night) and cars ahead at several distances with tail and brake lights; the headlight
  group is made to flicker too, so *all* vehicle lights can be synchronised.

Luminances are fixed (not drawn) inside upstream's ranges: tail lights 600 cd/m^2, brake lights 4000 cd/m^2,
headlights 6e4 cd/m^2 (:mod:`render_tools.scene`).
"""
from __future__ import annotations

import json
import math
import sys
from pathlib import Path

#: Directory of the figure scene files and render profiles, inside the package.
SCENE_DIR = Path(__file__).resolve().parent.parent / "configs" / "paper_figures"
#: Generator seed of the street (buildings, streetlights, road) of both scenes.
STREET_SEED = 11
#: Fixed luminances, cd/m^2.
TAIL_CD_M2, BRAKE_CD_M2, HEAD_CD_M2 = 600.0, 4000.0, 6.0e4


def _street(scene_id: str, speed_mps: float, short_exposure_s: float) -> tuple[dict, object]:
    """A generated night street with no vehicles, and a builder to add vehicles to it."""
    import numpy as np

    from render_tools import scene as S

    cfg = S.load_config()
    cfg["vehicles"].update({"ahead_same_dir": [0, 0], "oncoming": [0, 0], "parked_per_side": [0, 0]})
    cfg["road"]["lanes_per_direction"] = [2, 2]
    cfg["lights"]["billboards"] = [0, 0]
    sc = S.generate_scene(STREET_SEED, "night", config=cfg, scene_id=scene_id)
    # no traffic signal: the figures are about vehicle lights
    sig = {lt["instance"] for lt in sc["lights"] if lt["kind"] == "signal"}
    keep = [o for o in sc["objects"] if o["id"] not in sig]
    remap = {o["id"]: i for i, o in enumerate(keep)}
    for o in keep:
        o["id"] = remap[o["id"]]
    sc["lights"] = [lt for lt in sc["lights"] if lt["kind"] != "signal"]
    for i, lt in enumerate(sc["lights"]):
        lt["id"] = i
        lt["instance"] = remap.get(lt["instance"], -1)
    sc["objects"] = keep
    sc["groups"].pop("signals", None)
    sc["camera"].update({"position_m": [0.0, -1.75, 1.4], "pitch_deg": -1.0, "speed_mps": float(speed_mps),
                         "yaw_rate_rad_s": 0.0, "yaw_deg": 0.0})
    sc["timing"]["short_exposure_s"] = float(short_exposure_s)
    b = S.SceneBuilder(np.random.default_rng(STREET_SEED), cfg, "night")
    b.objects, b.lights, b.materials = sc["objects"], sc["lights"], sc["materials"]
    return sc, b


def _car(b, kind: str, x_m: float, y_m: float, heading_rad: float, braking: bool) -> None:
    """Add a parked vehicle with its lights on (tail lights, brake lights if ``braking``), fixed luminances."""
    from render_tools import scene as S

    n0 = len(b.lights)
    S.add_vehicle(b, kind, x_m, y_m, heading_rad, 0.0, lights_on=True, braking=braking, indicator=False)
    for lt in b.lights[n0:]:
        lt["luminance_cd_m2"] = {"headlight": HEAD_CD_M2, "tail": TAIL_CD_M2, "brake": BRAKE_CD_M2}[lt["kind"]]


def fig4_6_scene() -> dict:
    """Scene of Figs. 4-6: night street, ego 60 m/s, LPD 5 ms, parked vehicles with lights on (see module doc)."""
    from render_tools.scene import validate_scene

    sc, b = _street("paper_fig4_6", 60.0, 0.005)
    _car(b, "car", 13.0, -1.75, 0.0, braking=True)         # ego lane: the brake-light dropout (Figs. 4, 5)
    _car(b, "motorcycle", 9.9, -4.15, 0.0, braking=True)   # right lane, close to the image edge: the comet (Fig. 6)
    _car(b, "car", 20.0, -5.25, 0.0, braking=True)         # right lane
    _car(b, "car", 35.0, -5.4, 0.0, braking=False)         # right lane, further ahead
    _car(b, "car", 40.0, 5.25, math.pi, braking=False)     # oncoming lane: headlights
    return validate_scene(json.loads(json.dumps(sc)))


def fig7_scene() -> dict:
    """Scene of Fig. 7: the same street, static (speed 0); a motorcycle coming towards the camera and cars ahead."""
    from render_tools.scene import validate_scene

    sc, b = _street("paper_fig7", 0.0, 0.001)
    _car(b, "car", 10.0, -1.75, 0.0, braking=True)
    _car(b, "car", 18.0, -5.25, 0.0, braking=True)
    _car(b, "truck", 30.0, -1.9, 0.0, braking=False)
    _car(b, "motorcycle", 14.0, 1.9, math.pi, braking=False)  # oncoming lane: headlight towards the camera
    _car(b, "car", 45.0, 5.4, math.pi, braking=False)
    sc["groups"]["headlights"] = {"flicker": True}             # all vehicle lights are PWM-driven LEDs
    return validate_scene(json.loads(json.dumps(sc)))


def write_scenes(out_dir: str | Path = SCENE_DIR) -> list[Path]:
    """Write ``fig4_6_scene.json`` and ``fig7_scene.json`` into ``out_dir`` (atomic); returns the paths."""
    from render_tools.scene import save_scene

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = []
    for name, sc in (("fig4_6_scene.json", fig4_6_scene()), ("fig7_scene.json", fig7_scene())):
        save_scene(sc, out_dir / name)
        paths.append(out_dir / name)
    return paths


if __name__ == "__main__":  # pragma: no cover - maintainer tool
    for p in write_scenes(sys.argv[1] if len(sys.argv) > 1 else SCENE_DIR):
        print(p)
