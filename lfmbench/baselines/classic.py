"""Classic split-pixel fusion baselines: LPD only, SPD only, saturation fusion, flicker-aware and temporal fusion.

Every method takes the sample dict of ``docs/guide/contracts.md`` section 3 (a batch: leading B) and returns the HDR
estimate (B, F, 1, H, W) in the ``gt`` units: input-referred electrons, i.e. LPD-equivalent e- over the short
exposure. The sample's ``*_e`` keys are already in those units: ``lpd_hcg_e`` / ``lpd_lcg_e`` are the LPD
electrons, and ``spd_e`` = SPD electrons x sensitivity ratio (LPD/SPD, 100 for ``ovt``) x T_short / T_long.

Defines
-------
- :func:`saturated_fusion`: the functional core of the upstream "saturated" input-referred fusion.
- :func:`lpd_only`, :func:`spd_only`, :func:`upstream_saturated`, :func:`saturated_exposure_corrected`,
  :func:`flicker_aware`, :func:`flicker_aware_two_sided`, :func:`temporal`: the registered baselines.
- :class:`NoiseModel`: per-capture temporal noise in input-referred e-, from a sensor preset.

References
----------
- ISET-LFM upstream fusion (the upstream ISET-LFM repository, https://github.com/AyushJam/iset-lfm, its fusion step): saturated =
  volts >= 0.95 swing; both LPD unsaturated -> mean; only LCG unsaturated -> LCG; both saturated -> SPD x 100;
  else 0. No exposure-time correction.
- J. Solhusvik et al., "A 1280x960 2.8 um HDR CIS with DCG and split-pixel combined", IISW 2019 (three captures).
- EMVA Standard 1288 release 4.0 (2021), section 4: temporal noise = shot noise (variance = mean electrons) +
  read noise (variance sigma_d^2), the model behind :class:`NoiseModel`.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import torch

from lfmbench.baselines.base import REGISTRY

#: Noise-test factor of the flicker-aware fusion: the LPD must fall k standard deviations below the SPD.
NOISE_K = 3.0
#: Default sensor preset when the batch names none.
DEFAULT_PRESET = "ovt"
_CAPTURES = ("lpd_hcg_e", "lpd_lcg_e", "spd_e")


class BatchError(ValueError):
    """A batch lacks a key or has the wrong shape for a fusion method."""


def _get(batch: dict, key: str) -> torch.Tensor:
    if key not in batch:
        raise BatchError(f"batch has no key {key!r} (keys: {sorted(batch)})")
    x = batch[key]
    if not isinstance(x, torch.Tensor) or x.ndim != 5:
        raise BatchError(f"batch[{key!r}] must be a (B, F, C, H, W) tensor, got "
                         f"{tuple(x.shape) if isinstance(x, torch.Tensor) else type(x).__name__}")
    return x


def _captures(batch: dict) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    hcg, lcg, spd = (_get(batch, k) for k in _CAPTURES)
    sat = _get(batch, "saturated")
    if not (hcg.shape == lcg.shape == spd.shape) or hcg.shape[2] != 1:
        raise BatchError(f"lpd_hcg_e, lpd_lcg_e, spd_e must share the shape (B, F, 1, H, W), got {tuple(hcg.shape)}, "
                         f"{tuple(lcg.shape)}, {tuple(spd.shape)}")
    if sat.shape[:2] + sat.shape[3:] != hcg.shape[:2] + hcg.shape[3:] or sat.shape[2] != 3:
        raise BatchError(f"saturated must have shape (B, F, 3, H, W) matching the captures, got {tuple(sat.shape)}")
    return hcg, lcg, spd, sat.bool()


def _meta_value(meta, keys: tuple[str, ...], b: int):
    """First of ``keys`` found in ``meta`` (a dict, collated or not); nested 'exposures' dicts are searched too."""
    if not isinstance(meta, dict):
        return None
    for k in keys:
        if k in meta:
            v = meta[k]
            if isinstance(v, torch.Tensor):
                return float(v.reshape(-1)[b if v.numel() > 1 else 0])
            if isinstance(v, (list, tuple)):
                return v[b] if len(v) > 1 else v[0]
            return v
    if "exposures" in meta:
        return _meta_value(meta["exposures"], keys, b)
    return None


_SHORT_KEYS = ("short_s", "exposure_short_s", "t_short_s", "lpd_exposure_s", "lpd_s", "short")
_LONG_KEYS = ("long_s", "exposure_long_s", "t_long_s", "spd_exposure_s", "spd_s", "long")


def exposures_s(batch: dict) -> tuple[torch.Tensor, torch.Tensor]:
    """Short (LPD) and long (SPD) exposure times in s, per sample: two (B,) float64 tensors.

    Read from ``batch['meta']`` (keys ``exposure_short_s`` / ``exposure_long_s``, or an ``exposures`` dict with
    ``short_s`` / ``long_s``; see the accepted spellings in ``_SHORT_KEYS`` / ``_LONG_KEYS``).
    """
    meta = batch.get("meta", {})
    b = batch["gt"].shape[0] if "gt" in batch else _get(batch, "spd_e").shape[0]
    fast = _device_exposures(meta, b)
    if fast is not None:
        return fast
    ts, tl = [], []
    for i in range(b):
        s, l_ = _meta_value(meta, _SHORT_KEYS, i), _meta_value(meta, _LONG_KEYS, i)
        if s is None or l_ is None:
            raise BatchError("batch['meta'] must give the exposures in s (exposure_short_s / exposure_long_s or "
                             f"exposures={{'short_s', 'long_s'}}), got meta "
                             f"{sorted(meta) if isinstance(meta, dict) else meta}")
        if not (float(s) > 0 and float(l_) > 0):
            raise BatchError(f"exposures must be > 0 s, got short={s}, long={l_}")
        ts.append(float(s))
        tl.append(float(l_))
    return torch.tensor(ts, dtype=torch.float64), torch.tensor(tl, dtype=torch.float64)


def _device_exposures(meta, b: int) -> tuple[torch.Tensor, torch.Tensor] | None:
    """The exposures of a collated ``meta`` whose ``exposure_short_s``/``exposure_long_s`` are (B,) tensors on a
    GPU (the device path's batches), kept there: read sample by sample they would wait for the device at every
    value. Their positivity is asserted on the device (an error surfaces at the next synchronisation)."""
    if not isinstance(meta, dict):
        return None
    s, l_ = meta.get("exposure_short_s"), meta.get("exposure_long_s")
    if not (isinstance(s, torch.Tensor) and isinstance(l_, torch.Tensor) and s.device.type != "cpu"
            and s.shape == (b,) and l_.shape == (b,)):
        return None
    s, l_ = s.to(torch.float64), l_.to(torch.float64).to(s.device)
    torch._assert_async(torch.all((s > 0) & (l_ > 0)), "exposures must be > 0 s")
    return s, l_


def _bcast(v: torch.Tensor, like: torch.Tensor) -> torch.Tensor:
    return v.to(like.device, like.dtype).reshape((-1,) + (1,) * (like.ndim - 1))


@dataclass(frozen=True)
class NoiseModel:
    """Temporal noise of the three captures (EMVA 1288: shot + read noise).

    Attributes:
        read_noise_hcg_e, read_noise_lcg_e, read_noise_spd_e: read noise, e- rms, of each capture.
        sensitivity_ratio: LPD / SPD sensitivity (fill-factor ratio), dimensionless (100 for ``ovt``).
    """

    read_noise_hcg_e: float
    read_noise_lcg_e: float
    read_noise_spd_e: float
    sensitivity_ratio: float

    @classmethod
    def from_preset(cls, preset=DEFAULT_PRESET) -> "NoiseModel":
        """From a sensor preset (name, YAML path, mapping or ``SensorPreset``) via
        :func:`lfmbench.sensor.resolve`, which raises ValueError naming a bad field and file."""
        from lfmbench.sensor import resolve

        p = resolve(preset)
        c = p.captures
        return cls(float(c["lpd_hcg"].read_noise_e), float(c["lpd_lcg"].read_noise_e), float(c["spd"].read_noise_e),
                   float(p.sensitivity_ratio))

    @classmethod
    def from_batch(cls, batch: dict) -> "NoiseModel":
        """The noise model of the sensor in ``batch['meta']['sensor']`` (default ``ovt``).

        A resolved :class:`~lfmbench.sensor.SensorPreset` there (as :mod:`lfmbench.flicker_bench` puts it) is used
        as it is; a preset name or YAML path (as the datasets record it) is resolved by
        :func:`~lfmbench.sensor.load_preset`, whose per-file cache (keyed by modification time) parses it once per
        process; a name costs one ``stat``, no directory listing."""
        meta = batch.get("meta", {})
        name = _meta_value(meta, ("sensor", "sensor_preset", "preset"), 0) if isinstance(meta, dict) else None
        if isinstance(name, dict) and "captures" not in name:
            name = name.get("name", DEFAULT_PRESET)
        if name is None or isinstance(name, (str, Path)):
            return cls.from_preset(str(name or DEFAULT_PRESET))
        return cls.from_preset(name)

    def lpd_variance(self, lpd_e: torch.Tensor, both_unsaturated: torch.Tensor) -> torch.Tensor:
        """Variance (e-^2) of the LPD estimate: shot noise + read noise of the reads that were averaged.

        HCG and LCG read the same electrons, so their mean has the full shot variance and a quarter of the
        summed read variances; LCG alone has its own read variance.
        """
        read = torch.where(both_unsaturated,
                           torch.as_tensor((self.read_noise_hcg_e**2 + self.read_noise_lcg_e**2) / 4.0),
                           torch.as_tensor(self.read_noise_lcg_e**2)).to(lpd_e.dtype)
        return lpd_e.clamp_min(0.0) + read

    def spd_variance(self, spd_e: torch.Tensor, gain: torch.Tensor) -> torch.Tensor:
        """Variance (input-referred e-^2) of ``spd_e = gain x SPD electrons``: gain x spd_e + (gain x read)^2."""
        return gain * spd_e.clamp_min(0.0) + (gain * self.read_noise_spd_e) ** 2


def saturated_fusion(hcg: torch.Tensor, lcg: torch.Tensor, spd: torch.Tensor, saturated: torch.Tensor
                     ) -> torch.Tensor:
    """Upstream "saturated" input-referred fusion rule (functional core).

    both LPD reads unsaturated -> (HCG + LCG) / 2; only LCG unsaturated -> LCG; both saturated -> SPD;
    otherwise (HCG unsaturated while LCG saturated) -> 0, as upstream.

    Args:
        hcg, lcg, spd: (B, F, 1, H, W) input-referred values (e-); ``spd`` already scaled as the caller wants.
        saturated: (B, F, 3, H, W) bool, per capture (hcg, lcg, spd).

    Returns:
        (B, F, 1, H, W) fused estimate, unit of the inputs.
    """
    sh, sl = saturated[:, :, 0:1], saturated[:, :, 1:2]
    out = torch.zeros_like(lcg)
    out = torch.where(~sh & ~sl, 0.5 * (hcg + lcg), out)
    out = torch.where(sh & ~sl, lcg, out)
    out = torch.where(sh & sl, spd, out)
    return out


@REGISTRY.register("lpd_only")
def lpd_only(batch: dict) -> torch.Tensor:
    """LPD only: HCG where unsaturated, else LCG (clipped at its full well where that saturates too).

    Sharp but flickering: the reference point for flicker metrics. Returns (B, F, 1, H, W) e-.
    """
    hcg, lcg, _, sat = _captures(batch)
    return torch.where(sat[:, :, 0:1], lcg, hcg)


@REGISTRY.register("spd_only")
def spd_only(batch: dict) -> torch.Tensor:
    """SPD only: ``spd_e``, already scaled by the sensitivity ratio and T_short / T_long (input-referred).

    Flicker-free for PWM periods up to T_long but motion-blurred and noisier. Returns (B, F, 1, H, W) e-.
    """
    _, _, spd, _ = _captures(batch)
    return spd


@REGISTRY.register("upstream_saturated")
def upstream_saturated(batch: dict) -> torch.Tensor:
    """The upstream ISET-LFM 'saturated' fusion, faithful: SPD input-referred by the sensitivity ratio only.

    Upstream multiplies the SPD by 100 and does not correct for T_long / T_short, so where it falls back to
    the SPD it is too bright by T_long / T_short (about 2.2-3.7x). Here ``spd_e * T_long / T_short`` gives
    exactly that. Upstream's last step (rescale so the peak equals the LCG swing, a display normalisation) is
    left out so the output stays in the GT units. Returns (B, F, 1, H, W) e-.
    """
    hcg, lcg, spd, sat = _captures(batch)
    ts, tl = exposures_s(batch)
    return saturated_fusion(hcg, lcg, spd * _bcast(tl / ts, spd), sat)


@REGISTRY.register("saturated_exposure_corrected")
def saturated_exposure_corrected(batch: dict) -> torch.Tensor:
    """Upstream 'saturated' fusion with the exposure-time ratio corrected (SPD input-referred as ``spd_e``).

    Returns (B, F, 1, H, W) e-.
    """
    hcg, lcg, spd, sat = _captures(batch)
    return saturated_fusion(hcg, lcg, spd, sat)


def _flicker_test(batch: dict, k: float, noise: NoiseModel | None, two_sided: bool
                  ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Fused estimate, SPD, and the mask where the LPD disagrees with the SPD by more than k sigma."""
    hcg, lcg, spd, sat = _captures(batch)
    nm = noise or NoiseModel.from_batch(batch)
    ts, tl = exposures_s(batch)
    gain = _bcast(nm.sensitivity_ratio * ts / tl, spd)
    fused = saturated_fusion(hcg, lcg, spd, sat)
    lpd_ok = ~sat[:, :, 1:2]
    both_ok = ~sat[:, :, 0:1] & lpd_ok
    # Shot noise from the larger of the two readings: a noisy SPD dipping towards 0 must not shrink its own
    # sigma (that would flag plain background noise as flicker).
    level = torch.maximum(fused, spd)
    var = nm.lpd_variance(level, both_ok) + nm.spd_variance(level, gain)
    diff = spd - fused
    if two_sided:
        diff = diff.abs()
    flick = lpd_ok & (diff > k * var.sqrt())
    return fused, spd, flick


@REGISTRY.register("flicker_aware")
def flicker_aware(batch: dict, k: float = NOISE_K, noise: NoiseModel | None = None,
                  two_sided: bool = False) -> torch.Tensor:
    r"""Flicker-aware fusion: the exposure-corrected saturated fusion, but the SPD wherever the LPD falls
    below the SPD's prediction by more than ``k`` noise standard deviations.

    Test: :math:`S - L > k \sqrt{\sigma_L^2 + \sigma_S^2}` with :math:`\sigma_L^2 = M + \sigma_{read}^2`
    (LPD electrons) and :math:`\sigma_S^2 = g M + (g \sigma_{read,SPD})^2`, :math:`M = \max(L, S)`, :math:`g` =
    sensitivity ratio x T_short / T_long (EMVA 1288 shot + read noise, input-referred; the shot noise is
    evaluated at the larger reading so a noisy low SPD value does not shrink its own sigma). A light caught
    OFF by the short exposure reads far below the SPD, which integrated at least one PWM period.

    Args:
        batch: sample dict (B leading); noise taken from the preset in ``meta`` unless ``noise`` is given.
        k: test threshold in standard deviations.
        noise: optional :class:`NoiseModel`.
        two_sided: also take the SPD where the LPD is k sigma *above* it (light caught fully ON).

    Returns:
        (B, F, 1, H, W) e-.
    """
    fused, spd, flick = _flicker_test(batch, k, noise, two_sided)
    return torch.where(flick, spd, fused)


@REGISTRY.register("flicker_aware_two_sided")
def flicker_aware_two_sided(batch: dict) -> torch.Tensor:
    """:func:`flicker_aware` with ``two_sided=True`` (SPD wherever LPD and SPD disagree beyond the noise)."""
    return flicker_aware(batch, two_sided=True)


@REGISTRY.register("temporal")
def temporal(batch: dict, k: float = NOISE_K, reducer: str = "mean", noise: NoiseModel | None = None) -> torch.Tensor:
    """Temporal fusion over the F frames of the sequence.

    Pixels where the LPD and the SPD disagree beyond the noise (two-sided test of :func:`flicker_aware`) in
    any frame are flicker-prone; there every frame gets the per-pixel ``reducer`` ('mean', 'median' or
    'max') over the frames of the exposure-corrected saturated fusion; elsewhere the per-frame fusion is
    kept. With PWM phases spread over the frames, the frame mean of the LPD is an unbiased estimate of the
    time-averaged LED level (the GT); 'max' keeps a light visible whenever any frame caught it ON.

    Args:
        batch: sample dict; k, noise: as :func:`flicker_aware`; reducer: 'mean' | 'median' | 'max'.

    Returns:
        (B, F, 1, H, W) e-.
    """
    fused, _, flick = _flicker_test(batch, k, noise, two_sided=True)
    if reducer == "mean":
        red = fused.mean(dim=1, keepdim=True)
    elif reducer == "median":
        red = fused.median(dim=1, keepdim=True).values
    elif reducer == "max":
        red = fused.amax(dim=1, keepdim=True)
    else:
        raise ValueError(f"reducer must be 'mean', 'median' or 'max', got {reducer!r}")
    prone = flick.any(dim=1, keepdim=True)
    return torch.where(prone, red.expand_as(fused), fused)
