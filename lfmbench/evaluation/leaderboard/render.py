"""Presenting ranked rows: the Markdown table (:func:`leaderboard_markdown`), the JSON document
(:func:`leaderboard_json`), the console table (:func:`print_leaderboard`) and the quality-vs-run-time plot
(:func:`plot_quality_vs_runtime`). Columns, headers and directions come from the metric registry."""
from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Any

from lfmbench.evaluation import stats
from lfmbench.evaluation.conditions import bin_labels, load_bins
from lfmbench.evaluation.leaderboard.compare import identity
from lfmbench.evaluation.leaderboard.rank import PARETO_AXES, _check_sort_by, few_scenes
from lfmbench.evaluation.leaderboard.read import LEADERBOARD_FORMAT, LEADERBOARD_VERSION
from lfmbench.evaluation.results import COMPLETE, jsonable, num, per_scene, scene_means
from lfmbench.fileio import atomic_save_figure


#: Rows (best first) the quality-vs-run-time plot shows with their own marker, CI bar and legend entry; the others
#: are small grey points (a sweep's 10,000 legend entries took minutes to draw and could not be read).
PLOT_LABELLED = 20
#: Rows (best first) the console table shows; a line counts the others (every row is in the Markdown and JSON
#: files). Drawing a sweep's 10,000 rows with rich took about half of a 10,000-file leaderboard's time.
PRINT_ROWS = 50


def _ms(row: dict) -> str:
    """The run-time cell: median ms/MP, its interquartile range, ``!`` when the time moved."""
    iqr = row.get("ms_iqr")
    return (_fmt(row["ms_per_megapixel"], 1) + (f" [{_fmt(iqr[0], 1)}, {_fmt(iqr[1], 1)}]" if iqr else "")
            + (" !" if row.get("time_moved") else ""))


def _status_mark(row: dict) -> str:
    """`` (interrupted)`` etc. after the method name of a run whose status is not ``complete``."""
    return "" if row.get("status") == COMPLETE else f" ({row.get('status')}: not a complete result)"


def _fmt(v: Any, nd: int = 3) -> str:
    if v is None:
        return "-"
    if isinstance(v, bool):
        return str(v)
    if isinstance(v, int):
        return f"{v:,}"
    v = float(v)
    if math.isnan(v):
        return "-"
    if math.isinf(v):
        return "inf" if v > 0 else "-inf"
    return f"{v:.{nd}f}" if abs(v) < 1e4 else f"{v:.3g}"


def _ci(ci: list | None, nd: int) -> str:
    if not ci or any(math.isnan(num(x)) for x in ci):
        return "-"
    return f"[{_fmt(ci[0], nd)}, {_fmt(ci[1], nd)}]"


def _columns(rows: list[dict], where: str = "table") -> list:
    from lfmbench.metrics import columns

    return [s for s in columns(where) if any(not math.isnan(r[s.name]) for r in rows)]


def _vs_best(row: dict, nd: int) -> tuple[str, str]:
    vb = row.get("vs_best")
    if row["rank"] == 1:
        return "best", "-"
    if not vb:
        return "-", "-"
    sig = " *" if num(vb.get("p_holm")) < stats.ALPHA else ""
    return (f"{_fmt(vb['mean_diff'], nd)} {_ci(vb['ci'], nd)}", f"{_fmt(vb['p'])} / {_fmt(vb.get('p_holm'))}{sig}")


def leaderboard_markdown(rows: list[dict], sort_by: str | None = None) -> str:
    """The ranked table as GitHub Markdown, then the CIs of the main metrics and the breakdown by condition."""
    from lfmbench.metrics import PRIMARY

    sort_by = sort_by or PRIMARY
    spec = _check_sort_by(sort_by)
    nd = spec.digits
    cols = [s for s in _columns(rows) if s.name != sort_by]
    st = stats.settings()
    head = (["#", "method", f"{spec.header} [95 % CI]", "diff vs best [95 % CI]", "p / p Holm", "n"]
            + [s.header for s in cols] + ["Pareto", "ms/MP [IQR]", "params", "MACs/MP", "failed"])
    lines = [f"Ranked by `{sort_by}` ({spec.direction} is better; {spec.reference}). Intervals: "
             f"{int(st['confidence'] * 100)} % {st['ci']}, {st['n_resamples']} resamples, seed {st['seed']}; "
             f"n = scenes. Each method against the best: {st['paired_test']} (`*`: p Holm < {st['alpha']}). "
             f"Pareto: not dominated on ({', '.join(PARETO_AXES)}). Run time = median ms per output megapixel "
             "of the repeated calls after warm-up [interquartile range]; `!`: the time moved (the scored calls' "
             "median, or another run of the method, more than a factor 2 outside that range): not to be trusted.",
             "",
             "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        d, p = _vs_best(r, nd)
        cells = [str(r["rank"]), f"`{r['method']}`" + _status_mark(r),
                 f"{_fmt(r[sort_by], nd)} {_ci(r['ci'].get(sort_by), nd)}", d, p, str(r["n_scenes"])]
        cells += [_fmt(r[s.name], s.digits) for s in cols]
        cells += ["yes" if r.get("pareto") else ("no" if r.get("pareto") is False else "-"),
                  _ms(r), _fmt(r["params"]), _fmt(r["macs_per_megapixel"], 0),
                  f"{r['failed']}/{r['scenes']}"]
        lines.append("| " + " | ".join(cells) + " |")
    ci_cols = [s for s in _columns(rows, "console") if s.name != sort_by]
    if any(r["ci"] for r in rows) and ci_cols:
        lines += ["", f"{int(st['confidence'] * 100)} % confidence intervals over scenes:", "",
                  "| method | " + " | ".join(s.header for s in ci_cols) + " |", "|---|" + "---|" * len(ci_cols)]
        for r in rows:
            lines.append(f"| `{r['method']}` | " + " | ".join(_ci(r["ci"].get(s.name), s.digits) for s in ci_cols)
                         + " |")
    bd = [r for r in rows if r.get("breakdown")]
    if bd:
        lines += ["", f"`{sort_by}` by condition (value [95 % CI] (scenes); bins: `lfmbench/configs/conditions.yaml`):"]
        conds = list(bd[0]["breakdown"])
        for cond in conds:
            labels = [lab for lab in _all_labels(cond, bd) if any(lab in r["breakdown"].get(cond, {}) for r in bd)]
            if not labels:
                continue
            lines += ["", f"| {cond} | " + " | ".join(labels) + " |", "|---|" + "---|" * len(labels)]
            for r in bd:
                c = r["breakdown"].get(cond, {})
                lines.append(f"| `{r['method']}` | " + " | ".join(
                    f"{_fmt(c[lab]['value'], nd)} {_ci(c[lab]['ci'], nd)} ({c[lab]['n']})" if lab in c else "-"
                    for lab in labels) + " |")
    weights = [r for r in rows if r.get("checkpoint_sha256")]
    if weights:
        lines += ["", "Weights (content SHA-256 of each checkpoint, verified when it was loaded): " + "; ".join(
            f"`{r['method']}` {r['checkpoint_sha256'][:12]}" for r in weights) + "."]
    devs = sorted({str(r["device"]) for r in rows})
    threads = sorted({str(r["threads"]) for r in rows if r.get("threads") is not None})
    lines += ["", f"Device: {'; '.join(devs)}" + (f"; torch CPU threads: {', '.join(threads)}" if threads else "")
              + "."]
    few = few_scenes(rows)
    if few:
        lines += ["", few[0].upper() + few[1:] + "."]
    return "\n".join(lines) + "\n"


def _all_labels(cond: str, rows: list[dict]) -> list[str]:
    seen: list[str] = []
    for r in rows:
        for lab in r["breakdown"].get(cond, {}):
            if lab not in seen:
                seen.append(lab)
    try:
        order = bin_labels(load_bins()[cond])
        return sorted(seen, key=lambda x: order.index(x) if x in order else len(order))
    except (KeyError, ValueError):
        return seen


def leaderboard_json(rows: list[dict], runs: list[dict], sort_by: str | None = None,
                     conditions_file: str | Path | None = None, with_scenes: bool = True) -> dict:
    """The leaderboard as a JSON-ready dict: settings, corpus identity, metric versions and every row, then
    (``with_scenes``) each row's per-scene values (``per_scene``)."""
    from lfmbench.metrics import PRIMARY, REGISTRY

    sort_by = sort_by or PRIMARY
    spec = REGISTRY[sort_by]
    ident = identity(runs[0]) if runs else {}
    doc = jsonable({
        "format": LEADERBOARD_FORMAT, "version": LEADERBOARD_VERSION, "sort_by": sort_by,
        "metric": {"name": spec.name, "version": spec.version, "unit": spec.unit, "direction": spec.direction,
                   "reference": spec.reference},
        "statistics": stats.settings(), "pareto_axes": list(PARETO_AXES),
        "corpus": (runs[0].get("corpus") if runs else None), "protocol": ident,
        "bins": load_bins(conditions_file),
        "rows": [{k: v for k, v in r.items() if not k.startswith("_")} for r in rows],
    })
    if not with_scenes:
        return doc
    doc["per_scene"] = {str(r["method"]): (json.loads(r["_scenes_json"]) if r["_scenes"] is None else
                                           [_scene_jsonable(s) for s in r["_scenes"]]) for r in rows}
    return doc


#: How a sweep's leaderboard JSON is encoded: compact, by the C encoder (``json.dumps``).
_COMPACT = {"allow_nan": False, "separators": (",", ":")}


def leaderboard_json_text(rows: list[dict], runs: list[dict], sort_by: str | None = None,
                          conditions_file: str | Path | None = None) -> str:
    """``json.dumps(leaderboard_json(...), allow_nan=False, separators=(",", ":"))``, the same bytes, with each
    row's ``per_scene`` list taken as the text :func:`digest_run` serialised where the file was read (a sweep's
    JSON is mostly these lists: 73 MB for 10,000 files)."""
    head = json.dumps(leaderboard_json(rows, runs, sort_by, conditions_file, with_scenes=False), **_COMPACT)
    per: dict[str, str] = {}
    for r in rows:
        text = r.get("_scenes_json")
        per[str(r["method"])] = text if text is not None else _scenes_text(r["_scenes"])
    return head[:-1] + ',"per_scene":{' + ",".join(json.dumps(k) + ":" + v for k, v in per.items()) + "}}"


def _scenes_text(scenes: list[dict]) -> str:
    return json.dumps([_scene_jsonable(s) for s in scenes], **_COMPACT)


def digest_run(run: dict) -> dict:
    """What the leaderboard needs of one result (:func:`~lfmbench.evaluation.leaderboard.read.load_runs`'s
    ``digest``, run where the file was read: in a sweep, in the worker processes): the run without its sample
    records and with ``_digest``: ``means`` (each metric over scenes, as
    :func:`~lfmbench.evaluation.results.scene_means`), ``n_scenes``, ``scenes_json`` (its ``per_scene`` entries as
    the leaderboard JSON holds them, serialised) and ``stat`` (the file's size and modification time: a row that
    gets statistics reads its file again, :func:`~lfmbench.evaluation.leaderboard.rank.leaderboard_rows`)."""
    records = run.pop("scenes", None)
    records = records if isinstance(records, list) else []
    scenes = per_scene(records)
    st = os.stat(run["_path"])
    run["_digest"] = {"means": scene_means(scenes), "n_scenes": len(scenes), "scenes_json": _scenes_text(scenes),
                      "stat": [st.st_size, st.st_mtime_ns]}
    return run


def _scene_jsonable(scene: dict) -> dict:
    """``jsonable(scene)`` of one :func:`~lfmbench.evaluation.results.per_scene` entry, its metric and weight
    values (finite floats as they are) without a call per value: a sweep's JSON holds millions of them."""
    out = {}
    for k, v in scene.items():
        if (k == "metrics" or k == "weights") and type(v) is dict:
            out[str(k)] = {str(n): (x if type(x) is float and x - x == 0.0 else jsonable(x)) for n, x in v.items()}
        else:
            out[str(k)] = jsonable(v)
    return out


def plot_quality_vs_runtime(rows: list[dict], path: str | Path, metric: str | None = None) -> Path:
    """Scatter of ``metric`` (default the LED score) against run time (ms per megapixel, log axis), one point
    per method (legend), with the bootstrap CI of the metric as a vertical error bar."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from lfmbench.metrics import PRIMARY, REGISTRY

    metric = metric or PRIMARY
    fig, ax = plt.subplots(figsize=(7.6, 4.4), dpi=120)
    markers = "osD^vP*Xh<>p"
    rest = []
    for i, r in enumerate(rows):
        x, y = r["ms_per_megapixel"], r[metric]
        if math.isnan(x) or math.isnan(y) or math.isinf(y) or x <= 0:
            continue
        if i >= PLOT_LABELLED:  # a sweep: the rest as small grey points, one artist for all of them
            rest.append((x, y))
            continue
        lo, hi = (num(v) for v in (r.get("ci", {}).get(metric) or (float("nan"), float("nan"))))
        err = [[max(0.0, y - lo)], [max(0.0, hi - y)]] if math.isfinite(lo) and math.isfinite(hi) else None
        # a legend rather than text labels: methods of similar cost and quality overlap
        ax.errorbar([x], [y], yerr=err, fmt=markers[i % len(markers)], ms=6, capsize=3,
                    label=f"{r.get('rank', i + 1)}. {r['method']}")
    if rest:
        ax.scatter(*zip(*rest), s=4, c="0.6", zorder=0, label=f"{len(rest):,} more runs (ranks > {PLOT_LABELLED})")
    ax.legend(fontsize=7, loc="center left", bbox_to_anchor=(1.01, 0.5), frameon=False)
    ax.set_xscale("log")
    ax.margins(x=0.25, y=0.1)
    ax.set_xlabel("run time [ms per megapixel] (log)")
    spec = REGISTRY[metric] if metric in REGISTRY else None
    ax.set_ylabel(f"{spec.header if spec else metric} [{spec.unit if spec else ''}]")
    ax.set_title(f"Quality vs run time ({'higher' if spec is None or spec.higher_is_better else 'lower'} is better; "
                 f"bars: {int(stats.CONFIDENCE * 100)} % CI over scenes)", fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    path = atomic_save_figure(fig, path)
    plt.close(fig)
    return path


def print_leaderboard(rows: list[dict], sort_by: str | None = None, note: str = "") -> None:
    """Print the ranked rows as a rich table (the console metrics of the first :data:`PRINT_ROWS` rows; the Markdown
    file has every row and column)."""
    from rich.console import Console
    from rich.table import Table

    from lfmbench.metrics import PRIMARY

    sort_by = sort_by or PRIMARY
    spec = _check_sort_by(sort_by)
    cols = [s for s in _columns(rows, "console") if s.name != sort_by]
    console = Console()
    if not console.is_terminal:
        console = Console(width=180)
    table = Table(title=f"lfmbench leaderboard (ranked by {sort_by}{'; ' + note if note else ''})")
    heads = ["#", "method", f"{spec.header} [95% CI]", "p Holm vs best"] + [s.header for s in cols] + \
        ["ms/MP [IQR]", "params", "failed"]
    for h in heads:
        table.add_column(h, justify="left" if h == "method" else "right", no_wrap=h == "method")
    for r in rows[:PRINT_ROWS]:
        p = "best" if r["rank"] == 1 else (_fmt((r.get("vs_best") or {}).get("p_holm")))
        table.add_row(str(r["rank"]), r["method"] + _status_mark(r),
                      f"{_fmt(r[sort_by], spec.digits)} {_ci(r['ci'].get(sort_by), spec.digits)}", p,
                      *[_fmt(r[s.name], s.digits) for s in cols],
                      _ms(r), _fmt(r["params"]), f"{r['failed']}/{r['scenes']}")
    console.print(table)
    if len(rows) > PRINT_ROWS:
        console.print(f"{len(rows) - PRINT_ROWS:,} more rows (ranks > {PRINT_ROWS}): every row is in the Markdown "
                      "and JSON files", highlight=False)
    if any(r.get("time_moved") for r in rows[:PRINT_ROWS]):
        console.print("!: the run time moved (more than a factor 2 outside its timed range): not to be trusted",
                      highlight=False)
    few = few_scenes(rows)
    if few:
        console.print(few, style="yellow", highlight=False)
