"""HDR reconstruction metrics: PSNR-L, PSNR-mu, SSIM-mu, PU21-PSNR and ColorVideoVDP (JOD).

Defines
-------
- :func:`normalize_hdr`: scale prediction and reference by the reference's peak (or 99th percentile + tanh).
- :func:`mu_law`: the mu-law tone curve of the deghosting literature.
- :func:`psnr`, :func:`psnr_l`, :func:`psnr_mu`: peak signal-to-noise ratio on linear / tone-mapped values.
- :func:`ssim_mu`: SSIM on mu-law tone-mapped values (kornia's maintained implementation); :func:`ssim_map`
  the SSIM map of images in [0, 1].
- :func:`bayer_luminance`: 2x2 GRBG quad average, a luminance proxy of a raw mosaic.
- :func:`to_display_luminance`: input-referred sensor units -> absolute luminance on the reference display.
- :func:`pu21_psnr`, :func:`cvvdp_jod`: the Mantiuk group's perceptual metrics through ``pycvvdp`` (optional);
  :func:`perceptual_metrics` computes both in one pass (one luminance conversion per sample).

Units: the HDR tensors are in the ground truth's units (input-referred LPD-equivalent e- over the short
exposure, see ``docs/guide/contracts.md`` section 3); PSNR values are in dB; luminance in cd m^-2.

References
----------
- N. K. Kalantari and R. Ramamoorthi, "Deep high dynamic range imaging of dynamic scenes", ACM TOG 36(4), 2017
  (mu-law with mu = 5000, PSNR-L, PSNR-mu).
- E. Perez-Pellitero et al., "NTIRE 2021 challenge on high dynamic range imaging", CVPR-W 2021 (99th-percentile
  normalisation, tanh, then mu-law).
- Z. Wang, A. C. Bovik, H. R. Sheikh, E. P. Simoncelli, "Image quality assessment: from error visibility to
  structural similarity", IEEE TIP 13(4), 2004 (SSIM; Gaussian window sigma 1.5, K1 = 0.01, K2 = 0.03).
- R. K. Mantiuk, M. Azimi, "PU21: a novel perceptually uniform encoding for adapting existing quality metrics
  for HDR", Picture Coding Symposium 2021.
- R. K. Mantiuk et al., "ColorVideoVDP: a visual difference predictor for image, video and display
  distortions", ACM TOG 43(4), 2024 (package ``cvvdp`` on PyPI, import ``pycvvdp``).
"""
from __future__ import annotations

import contextlib
import importlib
import sys
import types
from typing import Literal

import torch
import torch.nn.functional as F

from lfmbench.check import check_same_shape, check_tensor

#: mu of the mu-law tone curve (Kalantari & Ramamoorthi 2017).
MU_DEFAULT = 5000.0
#: Display model handed to ColorVideoVDP / PU21 (ColorVideoVDP, Mantiuk et al. 2024: absolute linear luminance on an HDR display).
CVVDP_DISPLAY = "standard_hdr_linear"
#: Peak luminance of that display model, cd m^-2 (pycvvdp ``display_models.json``, 'standard_hdr_linear').
CVVDP_DISPLAY_PEAK_CD_M2 = 1500.0
#: SSIM Gaussian window (taps); sigma is fixed at 1.5 px by kornia (Wang et al. 2004).
SSIM_WINDOW = 11

Normalization = Literal["max", "p99_tanh"]


def _per_sample_amax(x: torch.Tensor) -> torch.Tensor:
    """Max over every dim but the first, shaped for broadcasting: (B, 1, ..., 1)."""
    return x.reshape(x.shape[0], -1).amax(dim=1).reshape((x.shape[0],) + (1,) * (x.ndim - 1))


#: torch.quantile's input limit (elements); larger inputs are subsampled with a regular stride.
_QUANTILE_MAX = 16_000_000


def _quantile(flat: torch.Tensor, q: float, dim: int = -1) -> torch.Tensor:
    """``torch.quantile`` along the last dim (``dim=-1`` or 1 for (B, N)), subsampling the last dim with a
    regular stride when the input exceeds torch's size limit."""
    step = -(-flat.numel() // _QUANTILE_MAX)
    if step > 1:
        flat = flat[..., ::step]
    return torch.quantile(flat.float(), q, dim=dim)


def normalize_hdr(pred: torch.Tensor, gt: torch.Tensor, mode: Normalization = "max",
                  eps: float = 1e-12) -> tuple[torch.Tensor, torch.Tensor]:
    """Scale an HDR pair to the reference's range, per sample.

    ``mode='max'``: divide both by the GT peak, clip to [0, 1] (Kalantari & Ramamoorthi 2017: HDR normalised
    to [0, 1] before the mu-law). ``mode='p99_tanh'``: divide by the GT's 99th percentile, then ``tanh``
    (NTIRE 2021 HDR challenge).

    Args:
        pred: estimate, shape (B, *), any linear unit (here input-referred e-).
        gt: reference, shape (B, *), same unit.
        mode: ``'max'`` or ``'p99_tanh'``.
        eps: floor of the divisor (same unit as ``gt``), so an all-dark reference does not divide by zero.

    Returns:
        (pred_n, gt_n), dimensionless, shape (B, *), in [0, 1].
    """
    check_same_shape(pred, gt, "pred", "gt")
    check_tensor(pred, "pred", min_dim=1)
    if mode == "max":
        scale = _per_sample_amax(gt).clamp_min(eps)
        return (pred / scale).clamp(0.0, 1.0), (gt / scale).clamp(0.0, 1.0)
    if mode == "p99_tanh":
        q = _quantile(gt.reshape(gt.shape[0], -1), 0.99, dim=1).to(gt.dtype)
        scale = q.reshape((gt.shape[0],) + (1,) * (gt.ndim - 1)).clamp_min(eps)
        return torch.tanh((pred / scale).clamp_min(0.0)), torch.tanh((gt / scale).clamp_min(0.0))
    raise ValueError(f"mode must be 'max' or 'p99_tanh', got {mode!r}")


def mu_law(h: torch.Tensor, mu: float = MU_DEFAULT) -> torch.Tensor:
    r"""mu-law tone curve :math:`T(H) = \log(1 + \mu H) / \log(1 + \mu)` (Kalantari & Ramamoorthi 2017).

    Args:
        h: normalised HDR values in [0, 1], any shape (dimensionless).
        mu: compression, default 5000.

    Returns:
        Tone-mapped values in [0, 1], same shape.

    Example:
        >>> float(mu_law(torch.tensor(1.0)))
        1.0
    """
    if mu <= 0:
        raise ValueError(f"mu must be > 0, got {mu}")
    # (a fill on the device, not a copy from the host: a copy would wait for the device's queue)
    return torch.log1p(mu * h) / torch.log1p(torch.full((), mu, dtype=h.dtype, device=h.device))


def psnr(pred: torch.Tensor, gt: torch.Tensor, peak: float | torch.Tensor = 1.0) -> torch.Tensor:
    r"""PSNR per sample: :math:`10 \log_{10}(\text{peak}^2 / \text{MSE})`, MSE over all dims but the first.

    Args:
        pred: shape (B, *).
        gt: shape (B, *), same unit as ``pred``.
        peak: the signal peak in that unit (scalar or (B,)).

    Returns:
        (B,) in dB; ``inf`` where pred == gt.

    Example (MSE = 0.01, peak 1 -> 20 dB):
        >>> round(float(psnr(torch.full((1, 4), 0.1), torch.zeros(1, 4))[0]), 6)
        20.0
    """
    check_same_shape(pred, gt, "pred", "gt")
    check_tensor(pred, "pred", min_dim=1)
    mse = (pred - gt).double().pow(2).reshape(pred.shape[0], -1).mean(dim=1)
    peak_t = torch.as_tensor(peak, dtype=torch.float64, device=pred.device)
    return (10.0 * torch.log10(peak_t**2 / mse)).to(pred.dtype if pred.is_floating_point() else torch.float32)


def psnr_l(pred: torch.Tensor, gt: torch.Tensor, mode: Normalization = "max") -> torch.Tensor:
    """PSNR-L: PSNR of the normalised linear HDR values, peak 1 (Kalantari & Ramamoorthi 2017).

    Args:
        pred, gt: shape (B, *), linear HDR in the same unit (input-referred e-).
        mode: normalisation, see :func:`normalize_hdr`.

    Returns:
        (B,) in dB.
    """
    p, g = normalize_hdr(pred, gt, mode)
    return psnr(p, g, 1.0)


def psnr_mu(pred: torch.Tensor, gt: torch.Tensor, mu: float = MU_DEFAULT,
            mode: Normalization = "max") -> torch.Tensor:
    """PSNR-mu: PSNR of mu-law tone-mapped normalised HDR, peak 1 (Kalantari & Ramamoorthi 2017).

    Args:
        pred, gt: shape (B, *), linear HDR in the same unit (input-referred e-).
        mu: mu-law compression (default 5000).
        mode: normalisation, see :func:`normalize_hdr`.

    Returns:
        (B,) in dB.
    """
    p, g = normalize_hdr(pred, gt, mode)
    return psnr(mu_law(p, mu), mu_law(g, mu), 1.0)


def ssim_mu_map(pred: torch.Tensor, gt: torch.Tensor, mu: float = MU_DEFAULT, mode: Normalization = "max",
                window_size: int = SSIM_WINDOW) -> torch.Tensor:
    """Per-pixel SSIM map of the mu-law tone-mapped images (Wang et al. 2004, ``kornia.metrics.ssim``).

    Uses kornia's maintained implementation (Gaussian window sigma 1.5, K1 = 0.01, K2 = 0.03, data range 1,
    reflect padding, eps = 0), which equals scikit-image ``structural_similarity(gaussian_weights=True,
    sigma=1.5, use_sample_covariance=False, data_range=1)`` away from the border.

    Args:
        pred, gt: shape (B, *, H, W), linear HDR in the same unit; every leading dim after B is treated as an
            independent single-channel image (frames, channels).
        mu: mu-law compression.
        mode: normalisation, see :func:`normalize_hdr`.
        window_size: odd number of Gaussian taps.

    Returns:
        (B, N, H, W) with N the product of the dims between B and H, dimensionless in [-1, 1].
    """
    check_same_shape(pred, gt, "pred", "gt")
    check_tensor(pred, "pred", min_dim=3)
    p, g = normalize_hdr(pred, gt, mode)
    return ssim_map(mu_law(p, mu), mu_law(g, mu), window_size)


def ssim_map(pred: torch.Tensor, gt: torch.Tensor, window_size: int = SSIM_WINDOW) -> torch.Tensor:
    """Per-pixel SSIM map of images with data range 1 (Wang et al. 2004, ``kornia.metrics.ssim``: Gaussian window
    sigma 1.5, K1 = 0.01, K2 = 0.03, reflect padding, eps = 0).

    Args:
        pred, gt: shape (B, *, H, W), values in [0, 1]; every leading dim after B is an independent
            single-channel image (frames, channels).
        window_size: odd number of Gaussian taps.

    Returns:
        (B, N, H, W) with N the product of the dims between B and H, dimensionless in [-1, 1].
    """
    import kornia

    check_same_shape(pred, gt, "pred", "gt")
    check_tensor(pred, "pred", min_dim=3)
    b, (h, w) = pred.shape[0], pred.shape[-2:]
    if min(h, w) <= window_size // 2:
        raise ValueError(f"pred is too small for SSIM: H, W = {h}, {w} must exceed window_size // 2 = {window_size // 2}")
    smap = kornia.metrics.ssim(pred.reshape(-1, 1, h, w), gt.reshape(-1, 1, h, w), window_size, max_val=1.0, eps=0.0)
    return smap.reshape(b, -1, h, w)


def ssim_mu(pred: torch.Tensor, gt: torch.Tensor, mu: float = MU_DEFAULT, mode: Normalization = "max",
            window_size: int = SSIM_WINDOW) -> torch.Tensor:
    """SSIM-mu: mean of :func:`ssim_mu_map` over frames and pixels (Wang et al. 2004 on mu-law images).

    Args:
        pred, gt: shape (B, *, H, W), linear HDR in the same unit (input-referred e-).
        mu, mode, window_size: see :func:`ssim_mu_map`.

    Returns:
        (B,) dimensionless in [-1, 1]; 1 for identical inputs.
    """
    return ssim_mu_map(pred, gt, mu, mode, window_size).reshape(pred.shape[0], -1).mean(dim=1)


def bayer_luminance(x: torch.Tensor) -> torch.Tensor:
    """Luminance proxy of a raw 2x2 CFA mosaic: mean of each 2x2 quad ((R + 2G + B) / 4 for GRBG/RGGB).

    Args:
        x: raw mosaic, shape (*, H, W) with H, W even, any linear unit.

    Returns:
        (*, H/2, W/2), same unit.
    """
    if x.ndim < 2:
        raise ValueError(f"x must have at least 2 dims (H, W), got shape {tuple(x.shape)}")
    h, w = x.shape[-2:]
    if h % 2 or w % 2:
        raise ValueError(f"x must have even H and W for a 2x2 CFA, got {h}x{w}")
    lead = x.shape[:-2]
    y = F.avg_pool2d(x.reshape(-1, 1, h, w), 2)
    return y.reshape(lead + (h // 2, w // 2))


def to_display_luminance(x: torch.Tensor, reference: torch.Tensor, cd_per_unit: float | None = None,
                         peak_cd_m2: float = CVVDP_DISPLAY_PEAK_CD_M2) -> tuple[torch.Tensor, float]:
    """Map linear HDR values to absolute luminance (cd m^-2) on the reference display.

    The sample dict carries input-referred electrons, not a radiometric calibration, so by default the
    reference's 99th percentile is shown at the display peak: ``L = x * peak_cd_m2 / p99(reference)``.
    Give ``cd_per_unit`` (cd m^-2 per input-referred e-) for a fixed absolute calibration instead.

    Args:
        x: linear HDR, shape (*), unit of ``reference``.
        reference: the ground truth, shape (*), input-referred e-.
        cd_per_unit: optional fixed scale, cd m^-2 per unit.
        peak_cd_m2: display peak luminance, cd m^-2.

    Returns:
        (luminance in cd m^-2 clipped at >= 0, the scale used in cd m^-2 per unit).
    """
    if cd_per_unit is None:
        q = float(_quantile(reference.detach().reshape(-1), 0.99))
        cd_per_unit = peak_cd_m2 / max(q, 1e-12)
    if not cd_per_unit > 0:
        raise ValueError(f"cd_per_unit must be > 0, got {cd_per_unit}")
    return (x * cd_per_unit).clamp_min(0.0), float(cd_per_unit)


# ---------------------------------------------------------------------------------------------- pycvvdp (lazy)
class CvvdpUnavailableError(ImportError):
    """Raised when the optional ``cvvdp`` package cannot be imported."""


_PYCVVDP = None


@contextlib.contextmanager
def _torchvision_shim():
    """Temporarily provide the two pure-Python torchvision symbols pycvvdp imports.

    The PyPI ``torchvision`` wheel links CUDA libraries, so it fails to import next to the CPU build of torch
    this project pins. pycvvdp needs only ``torchvision.transforms.GaussianBlur`` (for ColorVideoVDP and
    PU21) and ``torchvision.ops.MLP`` (for its ML variants, which lfmbench does not use). The shim is removed
    from ``sys.modules`` as soon as pycvvdp is imported.
    """
    import kornia

    class GaussianBlur(torch.nn.Module):
        """torchvision-compatible Gaussian blur (odd kernel, reflect padding) through kornia."""

        def __init__(self, kernel_size, sigma=(0.1, 2.0)):
            super().__init__()
            k = (kernel_size, kernel_size) if isinstance(kernel_size, int) else tuple(kernel_size)
            s = float(sigma) if isinstance(sigma, (int, float)) else float(sigma[0])
            self.kernel_size, self.sigma = k, (s, s)

        def forward(self, img):
            h, w = img.shape[-2:]
            y = kornia.filters.gaussian_blur2d(img.reshape(-1, 1, h, w), self.kernel_size, self.sigma,
                                               border_type="reflect")
            return y.reshape(img.shape)

    class MLP(torch.nn.Module):  # only referenced by pycvvdp's ML metrics, never built by lfmbench
        def __init__(self, *args, **kwargs):
            raise CvvdpUnavailableError("torchvision.ops.MLP is not available (torchvision does not import here)")

    saved = {k: v for k, v in sys.modules.items() if k == "torchvision" or k.startswith("torchvision.")}
    for k in saved:
        del sys.modules[k]
    tv = types.ModuleType("torchvision")
    tv.__path__ = []  # a package, so "from torchvision.x import y" resolves through sys.modules
    tr = types.ModuleType("torchvision.transforms")
    tr.GaussianBlur = GaussianBlur
    ops = types.ModuleType("torchvision.ops")
    ops.MLP = MLP
    tv.transforms, tv.ops = tr, ops
    sys.modules.update({"torchvision": tv, "torchvision.transforms": tr, "torchvision.ops": ops})
    try:
        yield
    finally:
        for k in ("torchvision", "torchvision.transforms", "torchvision.ops"):
            sys.modules.pop(k, None)
        sys.modules.update(saved)


def load_pycvvdp():
    """Import ``pycvvdp`` (package ``cvvdp``) lazily; raise :class:`CvvdpUnavailableError` with a hint if absent."""
    global _PYCVVDP
    if _PYCVVDP is not None:
        return _PYCVVDP
    try:
        _PYCVVDP = importlib.import_module("pycvvdp")
    except ModuleNotFoundError as exc:
        if exc.name and exc.name.split(".")[0] == "pycvvdp":
            raise CvvdpUnavailableError(
                "ColorVideoVDP / PU21 need the optional package 'cvvdp': pip install 'lfmbench[eval]' (in a source "
                "checkout: pip install -c constraints.txt -e '.[eval]'), or evaluate with --no-perceptual") from exc
        if not (exc.name and exc.name.split(".")[0] == "torchvision"):
            raise CvvdpUnavailableError(f"pycvvdp could not be imported: {exc}") from exc
        _PYCVVDP = _import_with_shim()
    except Exception:  # noqa: BLE001 - torchvision present but broken (CUDA wheel next to CPU torch)
        _PYCVVDP = _import_with_shim()
    return _PYCVVDP


def _import_with_shim():
    """Import pycvvdp with :func:`_torchvision_shim` in place; :class:`CvvdpUnavailableError` on failure."""
    for k in [k for k in sys.modules if k == "pycvvdp" or k.startswith("pycvvdp.")]:
        del sys.modules[k]
    try:
        with _torchvision_shim():
            return importlib.import_module("pycvvdp")
    except Exception as exc:  # pragma: no cover - depends on the installed packages
        raise CvvdpUnavailableError(f"pycvvdp could not be imported: {exc}") from exc


def cvvdp_version() -> str:
    """Installed cvvdp version string, or ``'unavailable'``."""
    try:
        from importlib.metadata import version

        return version("cvvdp")
    except Exception:
        return "unavailable"


def cvvdp_config(cd_per_unit: float | None = None) -> str:
    """The configuration string stored with every cvvdp-based result."""
    cal = "p99->peak" if cd_per_unit is None else f"{cd_per_unit:g} cd/m2 per e-"
    return (f"cvvdp {cvvdp_version()}; display={CVVDP_DISPLAY} (peak {CVVDP_DISPLAY_PEAK_CD_M2:g} cd/m2); "
            f"input=Y luminance of 2x2 CFA quads; calibration={cal}")


def _to_bcfhw_luminance(x: torch.Tensor) -> torch.Tensor:
    """(B, F, 1, H, W) raw mosaic -> (B, 1, F, H/2, W/2) luminance proxy."""
    if x.ndim != 5 or x.shape[2] != 1:
        raise ValueError(f"expected a raw sequence of shape (B, F, 1, H, W), got {tuple(x.shape)}")
    y = bayer_luminance(x[:, :, 0])  # (B, F, h, w)
    return y.unsqueeze(1)


def _display_pairs(pred: torch.Tensor, gt: torch.Tensor, cd_per_unit: float | None):
    """Per sample b: (prediction, reference) luminance videos (1, 1, F, H/2, W/2) in cd m^-2 on the display model."""
    for b in range(pred.shape[0]):
        lg, scale = to_display_luminance(gt[b:b + 1], gt[b:b + 1], cd_per_unit)
        lp, _ = to_display_luminance(pred[b:b + 1], gt[b:b + 1], scale)
        yield _to_bcfhw_luminance(lp).float(), _to_bcfhw_luminance(lg).float()


#: The metrics :func:`perceptual_metrics` can compute (registry names).
PERCEPTUAL_METRICS = ("pu21_psnr", "cvvdp_jod")


def perceptual_metrics(pred: torch.Tensor, gt: torch.Tensor, cd_per_unit: float | None = None, fps: float = 60.0,
                       which: tuple[str, ...] = PERCEPTUAL_METRICS) -> dict[str, torch.Tensor]:
    """PU21-PSNR and ColorVideoVDP of a batch in one pass: pycvvdp is loaded, the metric objects are built and
    each sample is converted to display luminance once, then every metric of ``which`` is computed.

    Args:
        pred, gt: raw sequences (B, F, 1, H, W) in input-referred e-; converted to luminance with
            :func:`bayer_luminance` and :func:`to_display_luminance` (cd m^-2) per sample.
        cd_per_unit: fixed calibration in cd m^-2 per e- (default: GT p99 at the display peak).
        fps: frame rate in s^-1 (frames are a video when F > 1; PU21-PSNR pools the MSE over frames).
        which: subset of :data:`PERCEPTUAL_METRICS`.

    Returns:
        name -> (B,) tensor: ``pu21_psnr`` in dB (PU21 units, peak = PU21(100 cd m^-2)), ``cvvdp_jod`` in JOD
        (10 = identical).
    """
    check_same_shape(pred, gt, "pred", "gt")
    check_tensor(pred, "pred", min_dim=5)
    unknown = [w for w in which if w not in PERCEPTUAL_METRICS]
    if unknown:
        raise ValueError(f"which: unknown perceptual metric(s) {unknown}; known: {list(PERCEPTUAL_METRICS)}")
    pc = load_pycvvdp()
    rate = fps if pred.shape[1] > 1 else 0
    pu = jod = None
    if "pu21_psnr" in which:
        # pycvvdp 0.5.7's vq_metric.set_display_model misses an import: pass the photometry object explicitly.
        photometry = pc.vvdp_display_photometry.load(CVVDP_DISPLAY, [])
        pu = pc.pu_psnr_y(display_photometry=photometry, device=pred.device)
        # vq_metric.predict misses the same import: the video source is built here.
        from pycvvdp.video_source import video_source_array
    if "cvvdp_jod" in which:
        jod = pc.cvvdp(display_name=CVVDP_DISPLAY, device=pred.device, quiet=True)
    out: dict[str, list] = {w: [] for w in which}
    for lp, lg in _display_pairs(pred, gt, cd_per_unit):
        with torch.no_grad():
            if pu is not None:
                vs = video_source_array(lp, lg, rate, dim_order="BCFHW", display_photometry=photometry)
                q, _ = pu.predict_video_source(vs)
                out["pu21_psnr"].append(torch.as_tensor(q, dtype=torch.float32).reshape(-1)[0])
            if jod is not None:
                q, _ = jod.predict(lp, lg, dim_order="BCFHW", frames_per_second=rate)
                out["cvvdp_jod"].append(torch.as_tensor(q, dtype=torch.float32).reshape(-1)[0])
    return {k: torch.stack(v) for k, v in out.items()}


def pu21_psnr(pred: torch.Tensor, gt: torch.Tensor, cd_per_unit: float | None = None,
              fps: float = 60.0) -> torch.Tensor:
    """PU21-PSNR (Mantiuk & Azimi 2021) through ``pycvvdp.pu_psnr_y`` on absolute luminance.

    Args:
        pred, gt: raw sequences (B, F, 1, H, W) in input-referred e-; converted to luminance with
            :func:`bayer_luminance` and :func:`to_display_luminance` (cd m^-2) per sample.
        cd_per_unit: fixed calibration in cd m^-2 per e- (default: GT p99 at the display peak).
        fps: frame rate in s^-1 (pycvvdp needs one for sequences; PU21-PSNR pools the MSE over frames).

    Returns:
        (B,) in dB (PU21 units, peak = PU21(100 cd m^-2)).
    """
    return perceptual_metrics(pred, gt, cd_per_unit, fps, which=("pu21_psnr",))["pu21_psnr"]


def cvvdp_jod(pred: torch.Tensor, gt: torch.Tensor, fps: float = 60.0,
              cd_per_unit: float | None = None) -> torch.Tensor:
    """ColorVideoVDP quality in JOD (10 = identical) of a video, judged with its temporal flicker.

    Args:
        pred, gt: raw sequences (B, F, 1, H, W) in input-referred e-; luminance as in :func:`pu21_psnr`.
        fps: frame rate in s^-1 (frames are treated as a video when ``fps > 0`` and F > 1).
        cd_per_unit: fixed calibration in cd m^-2 per e- (default: GT p99 at the display peak).

    Returns:
        (B,) JOD.
    """
    return perceptual_metrics(pred, gt, cd_per_unit, fps, which=("cvvdp_jod",))["cvvdp_jod"]
