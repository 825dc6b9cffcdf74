"""Compatibility module: ``from lfmbench.evaluate import ...`` keeps working.

The evaluation lives in the package :mod:`lfmbench.evaluation` (library modules and the command-line part
:mod:`lfmbench.evaluation.cli`); the dataset helpers :func:`make_dataset` and :func:`collate_samples` live in
:mod:`lfmbench.datasets`. This module re-exports the names it used to define.
"""
from lfmbench.datasets.loading import EmptyDataError, collate_samples, make_dataset
from lfmbench.evaluation import (COMPLETE, RESULT_FORMAT, RESULT_VERSION, DataSourceError, EvaluationInterrupted,
                                 IncomparableRunsError, MethodOutputError, benchmark, check_comparable,
                                 check_output, corpus_identity, count_params_macs, device_name, evaluate,
                                 git_revision, incomplete_runs, leaderboard_json, leaderboard_markdown,
                                 leaderboard_rows, load_runs, method_module, num, plot_quality_vs_runtime,
                                 print_leaderboard, time_method, versions, write_json_atomic)
from lfmbench.evaluation.cli import register
from lfmbench.metrics import columns as _columns

#: Metrics shown in the Markdown leaderboard, in column order (name, header): read from the metric registry.
LEADERBOARD_COLUMNS = tuple((s.name, s.header) for s in _columns("table"))

__all__ = ["COMPLETE", "RESULT_FORMAT", "RESULT_VERSION", "LEADERBOARD_COLUMNS", "DataSourceError",
           "EmptyDataError", "EvaluationInterrupted", "IncomparableRunsError", "MethodOutputError", "benchmark",
           "check_comparable", "check_output", "collate_samples", "corpus_identity", "count_params_macs",
           "device_name", "evaluate", "git_revision", "incomplete_runs", "leaderboard_json", "leaderboard_markdown",
           "leaderboard_rows", "load_runs", "make_dataset", "method_module", "num", "plot_quality_vs_runtime",
           "print_leaderboard", "register", "time_method", "versions", "write_json_atomic"]
