"""The leaderboard: rank evaluation results, with confidence intervals, paired tests and a breakdown by condition.

One module per job, in the order the data flows (each imports only those before it):

- :mod:`~lfmbench.evaluation.leaderboard.read`: :func:`load_runs` reads result files (one line naming the file and
  the field for anything that is not a valid result); :func:`incomplete_runs`.
- :mod:`~lfmbench.evaluation.leaderboard.compare`: :func:`check_comparable` refuses results computed on different
  corpora, with different metric versions or a different protocol (split, seed, crop, samples per scene, scoring
  options), naming the files and how they differ.
- :mod:`~lfmbench.evaluation.leaderboard.rank`: :func:`leaderboard_rows` ranks them by one registered metric
  (default :data:`lfmbench.metrics.PRIMARY`, the LED score): per-scene values from each result's sample records,
  bootstrap CIs over scenes, each method against the best (Wilcoxon signed-rank, Holm-adjusted), the Pareto front
  of LED score against PSNR-mu outside the LED regions, and the breakdown by condition.
- :mod:`~lfmbench.evaluation.leaderboard.render`: :func:`leaderboard_markdown`, :func:`leaderboard_json`,
  :func:`print_leaderboard`, :func:`plot_quality_vs_runtime` present them. Columns, headers and directions come
  from the metric registry.

This package face only re-exports (the names callers and tests have always imported from here).
"""
from lfmbench.evaluation.leaderboard.read import (LEADERBOARD_FORMAT, LEADERBOARD_VERSION, PARALLEL_READ_FILES,
                                                  _check_numbers, can_fork, incomplete_runs, load_runs, map_forked)
from lfmbench.evaluation.leaderboard.compare import (IncomparableRunsError, _display_identity, _draws, _names,
                                                     _OPTIONAL_FIELDS, _show, check_comparable,
                                                     comparability_problems, identity, run_reference,
                                                     run_sensor)
from lfmbench.evaluation.leaderboard.rank import (MIN_SCENES_FOR_CI, PARALLEL_STATS_ROWS, PARETO_AXES, STATS_ROWS,
                                                  _check_sort_by, _checkpoint_sha, _compare_with_best,
                                                  _flag_moved_times, _map_stats, _pair, _pareto, _pareto_pairwise,
                                                  _reread, _row_stats, few_scenes, leaderboard_rows)
from lfmbench.evaluation.leaderboard.render import (PLOT_LABELLED, PRINT_ROWS, _all_labels, _ci, _columns, _fmt, _ms,
                                                    _scene_jsonable, _status_mark, _vs_best, digest_run,
                                                    leaderboard_json, leaderboard_json_text, leaderboard_markdown,
                                                    plot_quality_vs_runtime, print_leaderboard)

__all__ = ["LEADERBOARD_FORMAT", "LEADERBOARD_VERSION", "PARALLEL_READ_FILES", "map_forked", "digest_run",
           "leaderboard_json_text", "load_runs", "incomplete_runs", "IncomparableRunsError",
           "identity", "run_reference", "run_sensor", "comparability_problems", "check_comparable", "PARETO_AXES",
           "STATS_ROWS",
           "PARALLEL_STATS_ROWS", "MIN_SCENES_FOR_CI", "can_fork", "few_scenes", "leaderboard_rows", "PLOT_LABELLED",
           "PRINT_ROWS", "leaderboard_markdown", "leaderboard_json", "print_leaderboard", "plot_quality_vs_runtime"]
