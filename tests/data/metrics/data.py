"""Tiny synthetic batches in the sample-dict layout of docs/guide/contracts.md section 3 (for the metrics,
baselines and evaluate tests; no corpus needed).

Scene: a horizontal radiance gradient, a moving bright LED disc (light 0) and a static LED disc (light 1).
The LEDs flicker in the LPD captures with explicit per-frame ON fractions, are steady at their time-averaged
level (duty x ON level) in the GT and, blurred along the motion, in the SPD. All values are input-referred e-.
"""
from __future__ import annotations

import torch

T_SHORT_S = 4e-3
T_LONG_S = 1.0 / 90.0
HCG_FULL_E = 5390.0  # 1.078 V / 200 uV/e- (ovt preset)
LCG_FULL_E = 22000.0
SPD_FULL_E = 7900.0
SENS_RATIO = 100.0
SPD_GAIN = SENS_RATIO * T_SHORT_S / T_LONG_S  # input-referred e- per SPD electron
SAT_FRACTION = 0.95


def disc(h: int, w: int, cy: float, cx: float, r: float) -> torch.Tensor:
    yy, xx = torch.meshgrid(torch.arange(h, dtype=torch.float64), torch.arange(w, dtype=torch.float64), indexing="ij")
    return ((yy - cy) ** 2 + (xx - cx) ** 2 <= r * r).double()


def make_batch(b: int = 1, f: int = 3, h: int = 32, w: int = 32, led_level: float = 20000.0, duty: float = 0.25,
               lpd_on: tuple[float, ...] = (0.0, 0.5, 1.0), static_on: tuple[float, ...] = (1.0, 0.0, 0.4),
               speed_px: float = 3.0, noise: bool = False, seed: int = 0, background: float = 300.0) -> dict:
    """A batch dict. ``lpd_on[t]`` (static_on[t]) = ON fraction of the short exposure in frame t for light 0 (1);
    light 0 moves ``speed_px`` per frame to the right and is blurred over +-speed_px/3 in the SPD."""
    g = torch.Generator().manual_seed(seed)
    bg = background * (0.5 + torch.linspace(0, 1, w, dtype=torch.float64)).expand(h, w)
    gt, lpd, spd, idx = [], [], [], []
    for t in range(f):
        cx0 = 8.0 + speed_px * t
        d0, d1 = disc(h, w, 10.0, cx0, 2.5), disc(h, w, 22.0, 22.0, 2.5)
        blur = sum(disc(h, w, 10.0, cx0 + s, 2.5) for s in torch.linspace(-speed_px / 3, speed_px / 3, 5).tolist()) / 5
        mean_level = duty * led_level
        gt.append(bg + mean_level * (d0 + d1))
        lpd.append(bg + led_level * (lpd_on[t % len(lpd_on)] * d0 + static_on[t % len(static_on)] * d1))
        spd.append(bg + mean_level * (blur + d1))
        li = torch.full((h, w), -1, dtype=torch.int64)
        li[d1 > 0] = 1
        li[d0 > 0] = 0
        idx.append(li)
    gt = torch.stack(gt)[None, :, None].expand(b, f, 1, h, w).clone()
    lpd = torch.stack(lpd)[None, :, None].expand(b, f, 1, h, w).clone()
    spd = torch.stack(spd)[None, :, None].expand(b, f, 1, h, w).clone()
    li = torch.stack(idx)[None, :, None].expand(b, f, 1, h, w).clone()
    if noise:
        lpd = lpd + torch.randn(lpd.shape, generator=g, dtype=torch.float64) * (lpd + 3.05**2).sqrt()
        spd = spd + torch.randn(spd.shape, generator=g, dtype=torch.float64) * (SPD_GAIN * spd).sqrt()
    hcg = lpd.clamp(0, HCG_FULL_E)
    lcg = lpd.clamp(0, LCG_FULL_E)
    spd = spd.clamp(0, SPD_FULL_E * SPD_GAIN)
    sat = torch.cat([lpd >= SAT_FRACTION * HCG_FULL_E, lpd >= SAT_FRACTION * LCG_FULL_E,
                     spd >= SAT_FRACTION * SPD_FULL_E * SPD_GAIN], dim=2)
    to_dn = lambda e, full: (64 + e / full * (4095 - 64)).round().clamp(0, 4095).float()  # noqa: E731
    return {
        "lpd_hcg": to_dn(hcg, HCG_FULL_E), "lpd_lcg": to_dn(lcg, LCG_FULL_E),
        "spd": to_dn(spd / SPD_GAIN, SPD_FULL_E),
        "lpd_hcg_e": hcg.float(), "lpd_lcg_e": lcg.float(), "spd_e": spd.float(),
        "saturated": sat, "gt": gt.float(), "light_index": li, "depth": torch.full((b, f, 1, h, w), 10.0),
        "meta": {"scene_id": [f"synth{seed}_{i}" for i in range(b)],
                 "exposure_short_s": torch.full((b,), T_SHORT_S, dtype=torch.float64),
                 "exposure_long_s": torch.full((b,), T_LONG_S, dtype=torch.float64),
                 "sensor": ["ovt"] * b},
    }


def noisy_batches(n=2, **kw):
    """``n`` noisy batches of :func:`make_batch` (seeds 0 .. n-1)."""
    return [make_batch(seed=i, noise=True, **kw) for i in range(n)]


def strict_load(path):
    """A result JSON read back refusing NaN/Infinity constants (the files must be standard JSON)."""
    import json  # noqa: PLC0415

    def no_const(x):
        raise AssertionError(f"non-standard JSON constant {x}")

    return json.loads(path.read_text(), parse_constant=no_const)
