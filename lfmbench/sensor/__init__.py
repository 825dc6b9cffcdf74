"""Capture physics: optics and the split-pixel HDR image sensor.

Spectral radiant exposure -> photo-electrons -> noise -> volts -> DN.

Functional core in torch (batched over any leading dimensions, CPU or CUDA, float32/float64 following the
input, no per-pixel Python loops) with a thin :class:`SplitPixelSensor` module. Defines:

- :class:`SensorPreset` (+ :class:`PhotodiodeSpec`, :class:`CaptureSpec`), loaded from YAML by
  :func:`load_preset` (``"ovt"``, ``"imx490"`` or a file path); invalid fields raise ``ValueError`` naming the
  field and file. :func:`resolve` is the one helper the rest of the package calls: a ``SensorPreset`` passes
  unchanged, a name is loaded (the commands resolve ``--sensor`` once and pass the object on).
- :class:`CFAPattern`: Bayer layouts by their top-left 2x2 cell (``GRBG`` default), with the kornia mapping.
- :func:`spectral_qe`, :func:`electron_weights`, :func:`ideal_electrons`: mean photo-electrons,
  n = sum_lambda H(lambda) dlambda A FF QE_c(lambda) lambda / (h c)  [Janesick2007]_ (photon energy h c / lambda).
- :func:`shot_noise`, :func:`fixed_pattern`, :func:`read_capture`, :func:`simulate_split_pixel`: the
  three-capture split pixel of ISET-LFM (LPD read at high and low conversion gain from the same electrons during
  the short exposure, SPD at 1/100 sensitivity during the long exposure), with the EMVA 1288 linear noise model
  [EMVA1288]_: Poisson shot noise of signal and dark current, DSNU/PRNU, Gaussian read noise, full-well and
  voltage-swing clipping, uniform quantisation.
- :func:`silicon_qe`: a documented internal-QE model of a silicon photodiode from Green's optical constants.

Signal chain of one capture (per pixel, e- unless stated):

1. mu = PRNU_gain * ideal electrons (photodiode's fill factor) + dark_current * T.
2. n = Poisson(mu) (rounded Gaussian N(mu, mu) when mu >= ``shot_noise_gaussian_above_e``), clipped to
   [0, full_well]. HCG and LCG read the same n.
3. v = (n + DSNU offset + read noise N(0, sigma_r^2)) * conversion gain, in V, clipped at the voltage swing.
4. DN = round(black_level + v * dn_per_volt), clipped to [0, 2^bits - 1]; dn_per_volt maps the voltage swing to
   the top code, dn_per_volt = (2^bits - 1 - black_level) / swing. System gain K = conversion_gain * dn_per_volt
   in DN/e-.
5. saturated = v >= saturation_fraction * swing (upstream ISET-LFM rule, fraction 0.95).
6. Input-referred: (DN - black_level) / K - dark_current * T in e- (the mean dark signal is removed, as optical-black
   clamping does, so its expectation is :func:`ideal_electrons` below saturation); SPD additionally
   x sensitivity_ratio x T_short / T_long, i.e. LPD-equivalent electrons over the short exposure
   (docs/guide/contracts.md, section 3).

References
----------
.. [EMVA1288] EMVA Standard 1288, "Standard for Characterization of Image Sensors and Cameras", Release 4.0
   Linear (2021): the linear camera model (sec. 2) and the photon-transfer method of the sensitivity, linearity
   and noise measurement.
.. [Janesick2007] J. R. Janesick, "Photon Transfer: DN -> lambda", SPIE Press (2007), ch. 2-5.
.. [Solhusvik2019] J. Solhusvik et al., "A 1280x960 2.8 um HDR CIS with DCG and Split-Pixel Combined",
   International Image Sensor Workshop (2019) - the 'ovt' preset, via ISETCam ``sensorCreate('ovt-large')``.
.. [Green2008] M. A. Green, "Self-consistent optical parameters of intrinsic silicon at 300 K including
   temperature coefficients", Sol. Energy Mater. Sol. Cells 92, 1305 (2008).
.. [Hecht2017] E. Hecht, "Optics", 5th ed. (2017), sec. 4.6: normal-incidence reflectance
   R = ((n - 1)^2 + k^2) / ((n + 1)^2 + k^2).

Modules, in the order the data flows through them:

- :mod:`lfmbench.sensor.optics`: the lens (camera equation, diffraction PSF): scene radiance -> irradiance.
- :mod:`lfmbench.sensor.spectral_data`: shipped spectral curves, band widths, the silicon QE model.
- :mod:`lfmbench.sensor.plan`: capture plans (exposure windows, readout) and the registry of architectures.
- :mod:`lfmbench.sensor.emva`: a preset from EMVA 1288 results (``lfmbench sensor fit``).
- :mod:`lfmbench.sensor.flicker_table`: each preset's captured PWM fraction (``lfmbench sensor flicker-table``).
- :mod:`lfmbench.sensor.preset`: the preset schema and its YAML files.
- :mod:`lfmbench.sensor.response`: spectral response, radiant exposure -> mean photo-electrons, the CFA.
- :mod:`lfmbench.sensor.noise`: the noise chain (torch) and :class:`SplitPixelSensor`.
- :mod:`lfmbench.sensor.fused`, :mod:`lfmbench.sensor.poisson` and the compiled kernels
  (``_poisson_kernel``, ``_readout_kernel``): the CPU form of the chain.

The public names are re-exported here: ``from lfmbench.sensor import simulate_split_pixel`` keeps working.
"""
from __future__ import annotations

from lfmbench.sensor.noise import (SplitPixelSensor, compand, decompand, fixed_pattern, read_capture, shot_noise,
                                   simulate_plan_electrons, simulate_split_pixel, simulate_split_pixel_electrons)
from lfmbench.sensor.preset import (CAPTURES, PHOTODIODES, PRESET_DIR, CaptureSpec, CFAPattern, Companding,
                                    PhotodiodeSpec, SensorPreset, Spectral, available_presets, load_preset,
                                    preset_from_dict, resolve)
from lfmbench.sensor.response import electron_weights, ideal_electrons, mosaic, spectral_qe
from lfmbench.sensor.spectral_data import DATA_DIR, band_widths_nm, read_spectral_csv, silicon_qe

__all__ = [
    "CAPTURES",
    "PHOTODIODES",
    "DATA_DIR",
    "PRESET_DIR",
    "CFAPattern",
    "PhotodiodeSpec",
    "CaptureSpec",
    "SensorPreset",
    "Spectral",
    "Companding",
    "compand",
    "decompand",
    "available_presets",
    "load_preset",
    "resolve",
    "preset_from_dict",
    "read_spectral_csv",
    "band_widths_nm",
    "spectral_qe",
    "electron_weights",
    "mosaic",
    "ideal_electrons",
    "fixed_pattern",
    "shot_noise",
    "read_capture",
    "simulate_split_pixel",
    "simulate_split_pixel_electrons",
    "simulate_plan_electrons",
    "SplitPixelSensor",
    "silicon_qe",
]
