"""lfmbench.datasets.options: the dataset's keyword arguments checked in groups, without a corpus, with the errors
of LFMCaptureDataset (the argument named; TypeError for a wrong type)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from lfmbench.datasets.options import DEFAULT_OUTPUTS, CacheOptions, SampleOptions, SimulationOptions


def test_defaults_and_normalised_values():
    o = SampleOptions.checked(crop=np.int64(8), groups="signals", seed=np.int32(3))
    assert (o.split, o.frames, o.crop, o.groups, o.seed, o.outputs) == ("train", 3, (8, 8), ("signals",), 3,
                                                                           DEFAULT_OUTPUTS)
    s = SimulationOptions.checked(noise=np.bool_(False))
    assert (s.shutter, s.noise, s.optics, s.pieces, s.noise_streams) == ("global", False, True, False, "generator")
    assert CacheOptions.checked(Path("c")) == CacheOptions(Path("c") / ".cache", 8)
    assert CacheOptions.checked(Path("c"), cache_dir=False, cache_scenes=0) == CacheOptions(None, 0)


@pytest.mark.parametrize("kw, exc, match", [
    ({"split": "tset"}, ValueError, r"^split must be one of \('train', 'val', 'test', 'all'\), got 'tset'$"),
    ({"frames": 0}, ValueError, "^frames must be a positive integer, got 0$"),
    ({"frame_start": "first"}, ValueError, "^frame_start must be an integer >= 0 or 'random'"),
    ({"crop": (8, 1)}, ValueError, r"^crop must be None, an int or \(h, w\) with sides >= 2"),
    ({"crop": 8.0}, ValueError, r"^crop must be None, an int or \(h, w\) of ints"),
    ({"outputs": ("gt", "hdr")}, ValueError, r"^outputs: unknown \['hdr'\]"),
    ({"groups": [1]}, ValueError, "^groups must be None or a list of light-group names"),
    ({"seed": True}, TypeError, "^seed must be an integer, got True$"),
    ({"max_lights": -1}, ValueError, r"^max_lights must be an integer in \[0, "),
])
def test_sample_option_errors(kw, exc, match):
    with pytest.raises(exc, match=match):
        SampleOptions.checked(**kw)


@pytest.mark.parametrize("kw, exc, match", [
    ({"shutter": "roling"}, ValueError, r"^shutter must be one of \('global', 'rolling'\), got 'roling'$"),
    ({"noise_streams": "philox"}, ValueError, "^noise_streams must be one of"),
    ({"static_windows": "far"}, ValueError, "^static_windows must be one of"),
    ({"optics": 1}, TypeError, "^optics must be True or False, got 1$"),
    ({"line_time_s": float("nan")}, ValueError, "^line_time_s must be None or a finite number > 0"),
])
def test_simulation_option_errors(kw, exc, match):
    with pytest.raises(exc, match=match):
        SimulationOptions.checked(**kw)
