"""ISP stage: a sensor's Bayer mosaic (a capture, a fusion estimate or the ground truth) -> display sRGB, in torch.

Functional core with thin ``nn.Module`` wrappers (kornia style), one registry per kind of operator, pipelines as
plain data (``lfmbench/configs/isp/*.yaml``). Modules, in the order the data flows through them:

- :mod:`lfmbench.isp.raw`: black level, white balance on the mosaic (preset gains or grey world).
- :mod:`lfmbench.isp.compand`: piecewise-linear companding of the sensor's HDR link (e.g. 24 -> 12 bit) and back.
- :mod:`lfmbench.isp.demosaic`: kornia's bilinear and Malvar-He-Cutler 2004 (registry ``DEMOSAIC``).
- :mod:`lfmbench.isp.color`: white-balance gains and the colour-correction matrix fitted from the preset's QE
  curves (ColorChecker under D65, error in CIE dE2000), sRGB encoding (IEC 61966-2-1).
- :mod:`lfmbench.isp.tonemap`: Reinhard 2002 (global), Durand-Dorsey 2002 (local), linear clip (registry
  ``TONEMAP``).
- :mod:`lfmbench.isp.pipeline`: the stage registry ``STAGES``, :class:`ISPPipeline` (from YAML) and :class:`ISP`
  (a pipeline bound to a preset; :meth:`ISP.pair` maps an estimate and its ground truth the same way).

The LED score and the other primary metrics stay on linear values; the ISP feeds the display-referred secondary
metrics (:mod:`lfmbench.metrics.display`). See ``docs/guide/isp.md``.
"""
from lfmbench.isp.color import (CCMFit, ColorCorrection, SRGBEncode, apply_ccm, camera_rgb, fit_ccm, luminance,
                                srgb_decode, srgb_encode, white_balance_gains)
from lfmbench.isp.compand import Compander, check_knees, compand, decompand
from lfmbench.isp.demosaic import (DEMOSAIC, Demosaic, clamp_to_neighbours, demosaic, demosaic_bilinear,
                                   demosaic_malvar2004)
from lfmbench.isp.pipeline import (ISP, STAGES, ISPPipeline, available_pipelines, load_pipeline,
                                   pipeline_from_dict)
from lfmbench.isp.raw import (BlackLevel, WhiteBalance, cfa_channel_map, gray_world_gains, subtract_black_level,
                              white_balance_mosaic)
from lfmbench.isp.tonemap import (TONEMAP, ToneMap, durand2002, durand2002_stats, exposure_clip, reinhard2002,
                                  reinhard2002_stats, tonemap)

__all__ = ["CCMFit", "ColorCorrection", "SRGBEncode", "apply_ccm", "camera_rgb", "fit_ccm", "luminance",
           "srgb_decode", "srgb_encode", "white_balance_gains", "Compander", "check_knees", "compand", "decompand",
           "DEMOSAIC", "Demosaic", "clamp_to_neighbours", "demosaic", "demosaic_bilinear", "demosaic_malvar2004",
           "ISP", "STAGES", "ISPPipeline", "available_pipelines", "load_pipeline", "pipeline_from_dict", "BlackLevel",
           "WhiteBalance", "cfa_channel_map", "gray_world_gains", "subtract_black_level", "white_balance_mosaic",
           "TONEMAP", "ToneMap", "durand2002", "durand2002_stats", "exposure_clip", "reinhard2002",
           "reinhard2002_stats", "tonemap"]
