"""render_tools.preview's tone mapping: Reinhard et al. 2002's photographic operator (eqs. 1-4 with white point)
computed by hand on a neutral ramp, with the key value taken from the scene's time of day (a night street is a
low-key scene)."""
from __future__ import annotations

import numpy as np
import pytest

from render_tools import preview as pv
from render_tools import spectra

BANDS = [400.0 + 10.0 * i for i in range(31)]


def _srgb_to_linear(v8: np.ndarray) -> np.ndarray:
    v = v8 / 255.0
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def test_the_key_comes_from_the_time_of_day():
    assert pv.key_for({"time_of_day": "night"}) == 0.045
    assert pv.key_for({"time_of_day": "day"}) == pv.key_for({"time_of_day": "dusk"}) == pv.KEY_VALUE == 0.18
    assert pv.key_for({}) == pv.KEY_VALUE


@pytest.mark.parametrize("key", [0.18, 0.045])
def test_the_tone_curve_is_reinhards_with_the_given_key(key):
    lum = np.geomspace(0.01, 100.0, 1000)                     # cd/m^2, one neutral ramp
    flat = np.ones((len(BANDS), 1, lum.size))
    y1 = spectra.spectral_to_xyz(flat, BANDS, 10.0)[1, 0, 0]  # cd/m^2 of unit radiance
    img = flat * (lum / y1)
    lw = np.exp(np.mean(np.log(pv.LUM_EPS + lum)))            # log-average (eq. 1)
    lm = key * lum / lw                                       # eq. 2
    white = np.percentile(lm, 99.9)
    ld = lm * (1 + lm / white**2) / (1 + lm)                  # eq. 4
    rgb = pv.tonemap_srgb(img, BANDS, 10.0, key=key)[0]       # (W, 3) uint8
    lin = _srgb_to_linear(rgb[:, 1].astype(float))
    ok = (rgb[:, 1] > 100) & (rgb[:, 1] < 250)                # 8-bit steps under 1 %, no clipping
    assert ok.sum() > 200
    ratio = lin[ok] / ld[ok]                                  # same chromaticity: display = ld x a constant
    assert np.ptp(ratio) / np.median(ratio) < 0.03


def test_a_low_key_darkens_the_mid_tones():
    lum = np.geomspace(0.01, 100.0, 1000)
    img = np.ones((len(BANDS), 1, lum.size)) * lum
    day = pv.tonemap_srgb(img, BANDS, 10.0, key=0.18)[0, :, 1]
    night = pv.tonemap_srgb(img, BANDS, 10.0, key=pv.key_for({"time_of_day": "night"}))[0, :, 1]
    mid = slice(400, 600)
    assert np.all(night[mid] < day[mid]) and np.median(day[mid]) - np.median(night[mid]) > 30


def test_the_led_lit_wet_night_is_the_same_street_with_white_streetlights():
    entries = {e[0]: e for e in pv.GALLERY}
    sodium = pv.gallery_scene(entries["v2_wet_night"], 7)
    led = pv.gallery_scene(entries["v2_wet_night_led"], 7)
    assert led["objects"] == sodium["objects"] and len(led["lights"]) == len(sodium["lights"])
    changed = [(a, b) for a, b in zip(sodium["lights"], led["lights"]) if a != b]
    assert changed and all(a["group"] == "streetlights" and dict(a, spectrum=None) == dict(b, spectrum=None)
                           for a, b in changed)
    assert {str(b["spectrum"]) for _, b in changed} == {str({"model": "illuminant", "name": "LED-B3"})}
