"""Torch datasets over an lfmbench corpus: split-pixel captures simulated on the fly.

Modules, in data-flow order: :mod:`~lfmbench.datasets.projection` (a scene's layers projected through the sensor's
spectral response and optics, cached), :mod:`~lfmbench.datasets.pwm` (PWM draws), :mod:`~lfmbench.datasets.assembly`
(composition and timing rules, the sample dict: one definition for both paths), :mod:`~lfmbench.datasets.pieces` (a
sample's unsimulated pieces), :mod:`~lfmbench.datasets.capture` (:class:`LFMCaptureDataset`, :class:`SceneView`; its
options: :mod:`~lfmbench.datasets.options`), :mod:`~lfmbench.datasets.batched` (captures simulated in batches on the
training device) and :mod:`~lfmbench.datasets.loading` (datasets and collation for training and evaluation).
"""
from lfmbench.datasets.assembly import check_line_time, compose_frame, window_bin_exposure
from lfmbench.datasets.capture import DatasetNotFoundError, LFMCaptureDataset, SceneView
from lfmbench.datasets.options import DEFAULT_OUTPUTS, OUTPUTS
from lfmbench.datasets.batch_compose import compose_batch
from lfmbench.datasets.batched import BatchedCaptureSimulator, collate_pieces, pieces_to, simulate_batch
from lfmbench.datasets.loading import EmptyDataError, collate_samples, make_dataset
from lfmbench.datasets.pwm import (TEST_SPLIT_SEED, PWMConfig, PWMParams, SceneDraw, draw_pwm, draw_scene_pwm,
                                   load_pwm_config)

__all__ = ["LFMCaptureDataset", "SceneView", "DatasetNotFoundError", "OUTPUTS", "DEFAULT_OUTPUTS", "compose_frame",
           "window_bin_exposure", "check_line_time", "PWMConfig", "load_pwm_config", "draw_pwm", "draw_scene_pwm",
           "PWMParams", "SceneDraw", "TEST_SPLIT_SEED",
           "BatchedCaptureSimulator", "make_dataset", "collate_samples", "EmptyDataError", "collate_pieces", "compose_batch", "pieces_to", "simulate_batch"]
