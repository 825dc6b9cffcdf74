"""Device-agnostic code, checked without a GPU: the functional core under a foreign default device.

On CUDA the usual bug is a tensor made without ``device=`` (it lands on the default device, the CPU) meeting
the CUDA inputs. Running the CPU pipeline inside ``with torch.device("meta")`` makes every such tensor a
*meta* tensor instead, which raises when it meets a CPU input or shows up as a meta output. The same holds for
users who call ``torch.set_default_device("cuda")``. ``tests/sensor/test_sensor.py::test_cuda_matches_cpu`` runs the
real thing where a GPU exists.
"""
from __future__ import annotations

import numpy as np
import torch

from lfmbench.flicker import pwm_exposure
from lfmbench.sensor.optics import DiffractionOptics, OpticsConfig, airy_kernel, apply_psf, simulate_optics
from lfmbench.sensor import SplitPixelSensor, fixed_pattern, load_preset, shot_noise, simulate_split_pixel

WL = [400.0 + 10 * i for i in range(31)]


def _pipeline() -> dict[str, torch.Tensor]:
    x = torch.linspace(0, 2e-6, 2 * 31 * 16 * 16, dtype=torch.float64, device="cpu").reshape(2, 31, 16, 16)
    L = x * 1e3  # radiance, W sr^-1 m^-2 nm^-1
    out: dict[str, torch.Tensor] = {}
    for k, v in simulate_split_pixel(x, x, "ovt", WL, 4e-3, 11.11e-3, noise=False).items():
        out[f"clean_{k}"] = v
    for k, v in simulate_split_pixel(x.float(), x.float(), "imx490", WL, torch.tensor([4e-3, 5e-3], device="cpu"), 11.11e-3,
                                     generator=torch.Generator().manual_seed(0)).items():
        out[f"noisy_{k}"] = v
    sensor = SplitPixelSensor("ovt", WL)
    out["module"] = sensor(x, x, 4e-3, 11.11e-3, generator=torch.Generator().manual_seed(1))["spd"]
    cfg = OpticsConfig(cos4=True)
    out["optics"] = simulate_optics(L, WL, cfg, 2.8e-6)
    out["optics_module"] = DiffractionOptics(WL, cfg)(L)
    k = airy_kernel(WL, 5.73, 2.8e-6, 4, dtype=torch.float64, device=x.device)
    out["psf_conv"] = apply_psf(x, k, method="conv")
    out["psf_fft"] = apply_psf(x, k, method="fft")
    out.update({f"fpn_{k}": v for k, v in fixed_pattern("ovt", 8, 8, device=x.device).items()})
    mu = torch.tensor([0.0, 0.3, 5.0, 50.0, 2e3, 2e5], device="cpu")
    out["shot_torch"] = shot_noise(mu, torch.Generator().manual_seed(2), 1000.0, backend="torch")
    out["shot_numba"] = shot_noise(mu, torch.Generator().manual_seed(2), 1000.0, backend="numba")
    t = torch.tensor(np.linspace(-0.02, 0.02, 50), device="cpu")
    out["pwm_torch"] = pwm_exposure(t, torch.tensor(4e-3, dtype=torch.float64, device="cpu"), 1 / 97.0, 0.3)
    return out


def test_pipeline_under_foreign_default_device():
    ref = _pipeline()
    with torch.device("meta"):
        got = _pipeline()
    wrong = [k for k in ref if got[k].device.type != "cpu"]
    assert not wrong, f"outputs created on the default device instead of the input's: {wrong}"
    differ = [k for k in ref if not torch.equal(got[k], ref[k])]
    assert not differ, f"results depend on the default device: {differ}"
