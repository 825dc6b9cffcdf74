"""Torch datasets over an lfmbench corpus: split-pixel captures simulated on the fly."""
from lfmbench.datasets.capture import (DEFAULT_OUTPUTS, OUTPUTS, DatasetNotFoundError, LFMCaptureDataset, check_line_time,
                                       compose_frame, window_bin_exposure)
from lfmbench.datasets.batched import (BatchedCaptureSimulator, collate_pieces, compose_batch, pieces_to,
                                       simulate_batch)
from lfmbench.datasets.loading import EmptyDataError, collate_samples, make_dataset
from lfmbench.datasets.pwm import (TEST_SPLIT_SEED, PWMConfig, PWMParams, SceneDraw, draw_pwm, draw_scene_pwm,
                                   load_pwm_config)

__all__ = ["LFMCaptureDataset", "DatasetNotFoundError", "OUTPUTS", "DEFAULT_OUTPUTS", "compose_frame",
           "window_bin_exposure", "check_line_time", "PWMConfig", "load_pwm_config", "draw_pwm", "draw_scene_pwm",
           "PWMParams", "SceneDraw", "TEST_SPLIT_SEED",
           "BatchedCaptureSimulator", "make_dataset", "collate_samples", "EmptyDataError", "collate_pieces", "compose_batch", "pieces_to", "simulate_batch"]
