"""Evaluation stage: score fusion methods, rank them with confidence intervals (``lfmbench evaluate`` and
``lfmbench leaderboard``).

Modules, in data-flow order: :mod:`~lfmbench.evaluation.provenance` (versions, device, git, corpus identity),
:mod:`~lfmbench.evaluation.cost` (timing, parameters, MACs), :mod:`~lfmbench.evaluation.conditions` (time of day,
PWM, ego speed and their bins), :mod:`~lfmbench.evaluation.stats` (bootstrap CIs, paired tests),
:mod:`~lfmbench.evaluation.results` (the result file: per-scene values, aggregates, breakdown),
:mod:`~lfmbench.evaluation.run` (:func:`evaluate`), :mod:`~lfmbench.evaluation.leaderboard` (ranking and
tables), :mod:`~lfmbench.evaluation.benchmark` (several methods on one corpus;
:mod:`~lfmbench.evaluation.protocol_run`: the protocol leaderboards of docs/results/) and
:mod:`~lfmbench.cli.evaluate` (the two commands). Result format: ``docs/guide/metrics.md`` ("Result files").
"""
import importlib

#: public name -> submodule that defines it; imported on first access (PEP 562), so that importing
#: :mod:`lfmbench.cli.evaluate` to register the commands does not import torch and the dataset.
_WHERE = {
    **dict.fromkeys(["EmptyDataError", "collate_samples", "make_dataset"], "lfmbench.datasets.loading"),
    **dict.fromkeys(["benchmark", "benchmark_sensors", "safe_name", "write_leaderboard"],
                    "lfmbench.evaluation.benchmark"),
    **dict.fromkeys(["count_params_macs", "method_module", "time_method"], "lfmbench.evaluation.cost"),
    **dict.fromkeys(["IncomparableRunsError", "check_comparable", "comparability_problems", "incomplete_runs",
                     "leaderboard_json", "leaderboard_markdown", "leaderboard_rows", "load_runs",
                     "plot_quality_vs_runtime", "print_leaderboard"], "lfmbench.evaluation.leaderboard"),
    **dict.fromkeys(["corpus_identity", "device_name", "git_revision", "versions"],
                    "lfmbench.evaluation.provenance"),
    **dict.fromkeys(["COMPLETE", "RESULT_FORMAT", "RESULT_VERSION", "num", "per_scene", "write_json_atomic"],
                    "lfmbench.evaluation.results"),
    **dict.fromkeys(["DataSourceError", "EvaluationInterrupted", "MethodOutputError", "check_output", "evaluate",
                     "evaluate_methods"], "lfmbench.evaluation.run"),
}


def __getattr__(name: str):
    if name in _WHERE:
        value = getattr(importlib.import_module(_WHERE[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'lfmbench.evaluation' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(list(globals()) + list(_WHERE))


__all__ = sorted(_WHERE)
