"""Fake benchmark protocols: a tiny protocol file (three scenes, 24 x 16 px, 2 frames) for end-to-end render
tests with the fake renderer, and edits of it for the error tests."""
from __future__ import annotations

from pathlib import Path

import yaml

from lfmbench.datasets.pwm import TEST_SPLIT_SEED, load_pwm_config


def tiny_protocol_dict() -> dict:
    """A valid protocol (as the YAML's data): one train, one val, one test scene; render 24 x 16 px."""
    return {
        "format": "lfmbench-protocol", "name": "tiny", "version": 1, "description": "test protocol",
        "render": {"width": 24, "height": 16, "spp": 2, "light_spp": 2, "bins": 2, "frames": 2},
        "storage": "compact",
        "pwm": {"test_split_seed": TEST_SPLIT_SEED, "distributions": load_pwm_config().to_dict()},
        "coverage": {"test": {"min_scenes": 1, "times_of_day": ["night"], "vehicle_kinds": ["motorcycle"],
                              "signals": ["green"], "ego_speed_range_mps": [12, 12]}},
        "scenes": {
            "train": [{"id": "tr_a", "seed": 11, "time_of_day": "day", "ego_speed_mps": 30,
                       "vehicle_kinds": ["truck"], "signal": "red"}],
            "val": [{"id": "va_a", "seed": 12, "time_of_day": "dusk", "ego_speed_mps": 20,
                     "vehicle_kinds": [], "signal": "none"}],
            "test": [{"id": "te_a", "seed": 13, "time_of_day": "night", "ego_speed_mps": 12,
                      "vehicle_kinds": ["motorcycle", "car"], "signal": "green"}],
        },
    }


def write_protocol(path: str | Path, data: dict | None = None) -> Path:
    """Write ``data`` (default :func:`tiny_protocol_dict`) as YAML to ``path``; returns the path."""
    path = Path(path)
    path.write_text(yaml.safe_dump(tiny_protocol_dict() if data is None else data, sort_keys=False))
    return path
