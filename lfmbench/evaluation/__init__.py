"""Evaluation stage: score fusion methods, rank them with confidence intervals (``lfmbench evaluate`` and
``lfmbench leaderboard``).

Modules, in data-flow order: :mod:`~lfmbench.evaluation.provenance` (versions, device, git, corpus identity),
:mod:`~lfmbench.evaluation.cost` (timing, parameters, MACs), :mod:`~lfmbench.evaluation.conditions` (time of day,
PWM, ego speed and their bins), :mod:`~lfmbench.evaluation.stats` (bootstrap CIs, paired tests),
:mod:`~lfmbench.evaluation.results` (the result file: per-scene values, aggregates, breakdown),
:mod:`~lfmbench.evaluation.run` (:func:`evaluate`), :mod:`~lfmbench.evaluation.leaderboard` (ranking and
tables), :mod:`~lfmbench.evaluation.benchmark` (several methods on one corpus) and
:mod:`~lfmbench.evaluation.cli` (the two commands). Result format: ``docs/metrics.md`` ("Result files").
"""
from lfmbench.datasets.loading import EmptyDataError, collate_samples, make_dataset
from lfmbench.evaluation.benchmark import benchmark, safe_name, write_leaderboard
from lfmbench.evaluation.cost import count_params_macs, method_module, time_method
from lfmbench.evaluation.leaderboard import (IncomparableRunsError, check_comparable, comparability_problems,
                                             incomplete_runs, leaderboard_json, leaderboard_markdown,
                                             leaderboard_rows, load_runs, plot_quality_vs_runtime, print_leaderboard)
from lfmbench.evaluation.provenance import corpus_identity, device_name, git_revision, versions
from lfmbench.evaluation.results import COMPLETE, RESULT_FORMAT, RESULT_VERSION, num, per_scene, write_json_atomic
from lfmbench.evaluation.run import (DataSourceError, EvaluationInterrupted, MethodOutputError, check_output,
                                     evaluate)

__all__ = ["evaluate", "benchmark", "check_output", "MethodOutputError", "EmptyDataError", "DataSourceError",
           "EvaluationInterrupted", "IncomparableRunsError", "COMPLETE", "RESULT_FORMAT", "RESULT_VERSION", "num",
           "per_scene", "write_json_atomic", "load_runs", "check_comparable", "comparability_problems",
           "incomplete_runs", "leaderboard_rows", "leaderboard_markdown", "leaderboard_json",
           "plot_quality_vs_runtime", "print_leaderboard", "write_leaderboard", "safe_name", "corpus_identity",
           "device_name", "git_revision", "versions", "count_params_macs", "method_module", "time_method",
           "make_dataset", "collate_samples"]
