"""Corpus storage benchmark: size, encode / decode time and error of each EXR storage option on one scene.

Every radiance layer of one scene (a static group's short / long window: C bands; a light's K x C bins) is read
from a corpus as float32 (W sr^-1 m^-2 nm^-1), then written again as a whole scene with each storage option
(:class:`lfmbench.corpus.Storage`: pixel type, per-layer power-of-two scale for HALF, mantissa rounding,
OpenEXR compression) through :class:`lfmbench.corpus.CorpusWriter`, and read back through
:class:`lfmbench.corpus.Corpus` (the reader the dataset uses). Reported per option:

* **size**: all files of the scene (EXR + JSON) in MB (1e6 bytes);
* **encode / decode**: ms per frame, median of ``--repeats`` runs on frame 0 (encode = ``encode_scene`` in
  memory, scale and error bookkeeping included; decode = ``Corpus.read_static`` / ``read_light_bins`` /
  ``read_aux`` of every file of the frame from the OS page cache, scale undone);
* **error**, end to end (file written, decoded, compared with the float32 input): energy-weighted relative
  error ``sum|x' - x| / sum x`` of the whole scene and the largest of any layer, and the largest relative error
  ``|x' - x| / x`` of a single value among the values >= 2^-20 (~1e-6, 120 dB) of their layer's peak.

Also measured: the error of a plain float16 cast without scale (what ``--half`` of format version 1 did before
its FLOAT fallback), and the energy-weighted difference between the short and long window of each static group
(two independent Monte Carlo estimates, plus motion blur: an upper bound of the render noise that rounding must
stay far below).

Writes ``docs/benchmarks/storage.md`` (whole file) and ``<out>/results.json``.

Run: ``.venv/bin/python benchmarks/bench_storage.py --corpus DIR [--scene ID]`` (about 20 min for a 640x360
scene on 2 shared cores) or ``--quick`` (renders a small 160x90 scene into ``<out>/corpus`` unless there, fewer
options, one repeat: ~2 min).
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from lfmbench import corpus as C  # noqa: E402
from lfmbench.fileio import atomic_write_bytes, atomic_write_text, load_json  # noqa: E402

S = C.Storage
#: (label, storage, note); the first entry is the reference (format version 1).
FULL = [
    ("FLOAT zip (v1)", S("float32", "zip"), "format version 1, lossless"),
    ("FLOAT pxr24", S("float32", "pxr24"), "PXR24 rounds FLOAT to 24 bits"),
    ("HALF m10 zip", S("float16", "zip"), "scaled HALF (preset float16)"),
    ("HALF m10 piz", S("float16", "piz"), ""),
    ("HALF m10 b44", S("float16", "b44", allow_lossy_codec=True),
     "lossy on every HALF channel (and it can make radiance negative: the reader refuses such files); not allowed"),
    ("HALF m10 zstd", S("float16", "zstd", allow_lossy_codec=True), "needs OpenEXR >= 3.4; not allowed"),
    ("HALF m8 piz", S("float16", "piz", 8), ""),
    ("HALF m5 zip", S("float16", "zip", 5), ""),
    ("HALF m5 piz", S("float16", "piz", 5), ""),
    ("HALF m4 piz", S("float16", "piz", 4), ""),
]
QUICK_LABELS = ("FLOAT zip (v1)", "HALF m10 zip", "HALF m8 piz", "HALF m5 zip", "HALF m5 piz")
#: Values at or above this fraction of their layer's peak enter the per-value maximum error (2^-20, 120 dB).
PRECISION_FLOOR = 2.0 ** -C.HALF_PRECISION_RANGE_LOG2
TARGET_MB = 120.0


def load_scene(corpus: C.Corpus, sid: str) -> tuple[dict, dict, list[dict]]:
    """scene.json, meta.json and the renderer-style frame dicts of ``sid`` (float32 radiance, W sr^-1 m^-2 nm^-1)."""
    meta = corpus.meta(sid)
    return corpus.scene(sid), meta, read_back(corpus, sid, meta, range(meta["frames"]))


def layers(frames: list[dict]):
    """Yield ``(frame, name, key, array)`` for every radiance layer (key selects it in another frame list)."""
    for fr in frames:
        n = fr["frame"]
        for g, wins in fr["static"].items():
            for w in C.STATIC_WINDOWS:
                yield n, f"f{n:03d}/{g} [{w}]", ("static", g, w), wins[w]
        for g, ls in fr["lights"].items():
            for i, (lid, _, arr) in enumerate(ls):
                yield n, f"f{n:03d}/{g} light{lid}", ("lights", g, i), arr


def read_back(corpus: C.Corpus, sid: str, meta: dict, frame_ids) -> list[dict]:
    """Decode the given frames through the corpus reader (every file, scale undone)."""
    out = []
    for n in frame_ids:
        fr = {"frame": n, "static": {}, "lights": {}}
        for g in meta["groups"]:
            if C.group_storage(meta, g) == "static":
                fr["static"][g] = {w: corpus.read_static(sid, n, g, w) for w in C.STATIC_WINDOWS}
            else:
                fr["lights"][g] = corpus.read_light_bins(sid, n, g)
        if corpus.path(sid, n, "aux").is_file():
            fr["aux"] = corpus.read_aux(sid, n)
        out.append(fr)
    return out


def pick(frames: list[dict], n: int, key: tuple) -> np.ndarray:
    kind, g, sub = key
    fr = frames[n]
    return fr["static"][g][sub] if kind == "static" else fr["lights"][g][sub][2]


def errors(orig: list[dict], back: list[dict]) -> dict:
    """End-to-end errors (dimensionless) of ``back`` against ``orig`` (see module docstring)."""
    num = den = 0.0
    worst_layer = worst_value = 0.0
    worst_name = ""
    for n, name, key, x in layers(orig):
        y = pick(back, n, key)
        d = np.abs(y - x)  # float32: exact for nearby values (Sterbenz); sums in float64
        tot = float(x.sum(dtype=np.float64))
        dsum = float(d.sum(dtype=np.float64))
        num += dsum
        den += tot
        if tot > 0:
            e = dsum / tot
            if e > worst_layer:
                worst_layer, worst_name = e, name
            sel = x >= float(x.max()) * PRECISION_FLOOR
            worst_value = max(worst_value, float(np.max(d[sel] / x[sel])))
    return {"energy_error": num / max(den, 1e-300), "max_layer_energy_error": worst_layer,
            "worst_layer": worst_name, "max_value_error": worst_value}


def unscaled_half_error(orig: list[dict]) -> dict:
    """Errors of a plain float16 cast (no scale): energy-weighted, and the share of non-zero values lost (0)."""
    num = den = 0.0
    lost = nonzero = 0
    for _, _, _, x in layers(orig):
        h = x.astype(np.float16).astype(np.float64)
        num += float(np.abs(h - x).sum())
        den += float(x.sum(dtype=np.float64))
        lost += int(((h == 0) & (x > 0)).sum())
        nonzero += int((x > 0).sum())
    return {"energy_error": num / max(den, 1e-300), "lost_share": lost / max(nonzero, 1)}


def mc_difference(orig: list[dict]) -> float:
    """Energy-weighted |short - long| / long over the static groups (MC noise of two estimates + motion)."""
    num = den = 0.0
    for fr in orig:
        for wins in fr["static"].values():
            num += float(np.abs(wins["short"].astype(np.float64) - wins["long"]).sum())
            den += float(wins["long"].sum(dtype=np.float64))
    return num / max(den, 1e-300)


def bench_one(label: str, st: C.Storage, scene: dict, meta: dict, frames: list[dict], work: Path,
              repeats: int) -> dict:
    sid = meta["scene_id"]
    root = work / "c"
    shutil.rmtree(root, ignore_errors=True)
    w = C.CorpusWriter(root, dtype=st)
    w.write_scene(sid, scene, meta, frames)
    size = sum(p.stat().st_size for p in (root / C.SCENES_DIR / sid).rglob("*") if p.is_file())
    exr = {p.name: p.stat().st_size for p in (root / C.SCENES_DIR / sid / "f000").glob("*.exr")}
    corpus = C.Corpus(root, cache_size=0, check_values=False)  # a lossy codec may make values negative
    back = read_back(corpus, sid, meta, range(meta["frames"]))
    err = errors(frames, back)
    err["negative_values"] = sum(int((x < 0).sum()) for *_, x in layers(back))
    enc, dec = [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        for _ in _encode_frame0(meta, frames, st):
            pass
        enc.append(time.perf_counter() - t0)
        c2 = C.Corpus(root, cache_size=1, check_values=not err["negative_values"])
        t0 = time.perf_counter()
        read_back(c2, sid, meta, [0])
        dec.append(time.perf_counter() - t0)
    res = {"label": label, "storage": {**st.to_dict(), "allowed": not st.allow_lossy_codec},
           "size_mb": size / 1e6, "frame0_files_mb": {k: v / 1e6 for k, v in sorted(exr.items())},
           "encode_ms_per_frame": 1e3 * statistics.median(enc), "decode_ms_per_frame": 1e3 * statistics.median(dec),
           **err, "notes": list(w.notes)}
    print(f"{label:18s} {res['size_mb']:7.1f} MB  enc {res['encode_ms_per_frame']:6.0f} ms  "
          f"dec {res['decode_ms_per_frame']:5.0f} ms  energy err {err['energy_error']:.2e} (layer max "
          f"{err['max_layer_energy_error']:.2e})  value max {err['max_value_error']:.2e}  negative "
          f"{err['negative_values']}", flush=True)
    return res


def _encode_frame0(meta: dict, frames: list[dict], st: C.Storage):
    """Encode frame 0's files with the per-file encoders, as :func:`lfmbench.corpus.encode_scene` does."""
    fr = frames[0]
    bands, H, W = meta["bands_nm"], meta["height"], meta["width"]
    for g, wins in fr["static"].items():
        yield g, C.encode_static_exr(wins, bands, dtype=st, what=g)
    for g, ls in fr["lights"].items():
        bins = int(meta["groups"][g].get("bins", meta["timing"]["bins"]))
        yield g, C.encode_lights_exr(ls, bands, bins, H, W, dtype=st, what=g)
    if fr.get("aux"):
        yield "aux", C.encode_aux_exr(fr["aux"], H, W)


def exrheader_check(work: Path, results: list[dict], scene, meta, frames) -> dict:
    """Which storages the system's ``exrheader`` (often an older OpenEXR) can open."""
    tool = shutil.which("exrheader")
    if tool is None:
        return {}
    ver = subprocess.run(["dpkg-query", "-W", "-f=${Version}", "openexr"], capture_output=True, text=True).stdout
    out = {"tool": tool, "version": ver.strip() or "?", "ok": {}}
    for label, st, _ in FULL:
        if label not in {r["label"] for r in results}:
            continue
        data = C.encode_static_exr({w: a[:, :4, :4] for w, a in next(iter(frames[0]["static"].values())).items()},
                                   meta["bands_nm"], dtype=st)
        p = work / "h.exr"
        atomic_write_bytes(p, data)
        r = subprocess.run([tool, str(p)], capture_output=True, text=True)
        out["ok"][label] = r.returncode == 0 and "lfmbench_scale_short" in r.stdout
    return out


def choose(results: list[dict]) -> dict | None:
    """The allowed option within TARGET_MB with the smallest energy-weighted error (ties: the smaller files; not the
    faster decode, whose differences of a few % between codecs are within the timing noise of shared cores)."""
    ok = [r for r in results if r["storage"]["allowed"] and r["size_mb"] <= TARGET_MB and not r["negative_values"]]
    return min(ok, key=lambda r: (round(r["energy_error"], 5), r["size_mb"])) if ok else None


def is_default(r: dict) -> bool:
    """Whether result ``r`` measured the storage of new corpora (``lfmbench.corpus.STORAGES[DEFAULT_STORAGE]``)."""
    want = C.STORAGES[C.DEFAULT_STORAGE].to_dict()
    return {k: r["storage"].get(k) for k in want} == want


def write_doc(path: Path, info: dict, results: list[dict], chosen: dict | None) -> None:
    m = info["meta"]
    lines = [
        "# Corpus storage benchmark",
        "",
        f"Generated by `benchmarks/bench_storage.py` ({info['cmd']}) on {info['date']}, {info['machine']}, "
        f"1-minute load average {os.getloadavg()[0]:.1f} when the page was written. "
        "Every number below comes from that run; rerun the command to refresh this file.",
        "",
        f"Scene `{m['scene_id']}` of `{info['corpus']}`: {m['width']}x{m['height']} pixels, {m['frames']} frames, "
        f"{len(m['bands_nm'])} bands {m['bands_nm'][0]:g}-{m['bands_nm'][-1]:g} nm, K = {m['timing']['bins']} bins, "
        f"groups {', '.join(f'{g} ({C.group_storage(m, g)})' for g in m['groups'])}; "
        f"{info['n_layers']} radiance layers, {info['n_values'] / 1e6:.1f} M values. Input: the corpus as stored "
        f"({info['input_storage']}); its render record: `{json.dumps(info['render'])}` "
        "(`lfmbench render --out DIR --scenes 1 --seed SEED --profile default --storage float32` makes such a "
        "scene).",
        "",
        "Columns: size of all files of the scene (MB = 1e6 bytes); encode / decode time per frame, ms, median of "
        f"{info['repeats']} runs on frame 0 (encode in memory incl. scale and error bookkeeping; decode through "
        "`Corpus.read_*`, scale undone, files in the page cache; 2 CPU cores shared with other work, so times are "
        "upper bounds); energy-weighted relative error `sum|x' - x| / sum x` of the scene and of the worst layer; "
        "largest relative error of a single value among values >= 2^-20 (120 dB) of their layer's peak. "
        "Errors are end to end (written, decoded, compared with the float32 input).",
        "",
        "| option | allowed | size MB | encode ms/frame | decode ms/frame | energy err (scene) | energy err "
        "(worst layer) | max value err (>= 2^-20 peak) | negative values |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in results:
        mark = " **(default)**" if is_default(r) else ""
        lines.append(f"| {r['label']}{mark} | {'yes' if r['storage']['allowed'] else 'no'} | {r['size_mb']:.1f} | "
                     f"{r['encode_ms_per_frame']:.0f} | {r['decode_ms_per_frame']:.0f} | {r['energy_error']:.2e} | "
                     f"{r['max_layer_energy_error']:.2e} | {r['max_value_error']:.2e} | {r['negative_values']} |")
    base = results[0]
    lines += ["", "Notes on the options:", ""]
    for label, st, note in FULL:
        if note and label in {r["label"] for r in results}:
            lines.append(f"- {label}: {note}.")
    lines += [
        "- `mN`: mantissas rounded to N explicit bits before compression (relative error <= 2^-(N+1) per value "
        "in the precision range); m10 = plain HALF.",
        "- HALF layers are scaled by a power of two so that their peak lies in [2^(P-1), 2^P), P = 20 - 23 + N: "
        "values down to 2^-20 of the peak keep N bits (`docs/guide/corpus-format.md` section 6).",
        "- Not in the default run (to keep it near 20 min on 2 cores): ZIPS, DWAA, DWAB, PXR24 on HALF, HTJ2K and "
        "more mantissa widths; add them to `FULL` in the script to measure them.",
        "",
        "## Context",
        "",
        f"- Plain float16 without scale (format version 1 `--half` before its FLOAT fallback): energy-weighted "
        f"error {info['unscaled_half']['energy_error']:.2e}, {100 * info['unscaled_half']['lost_share']:.1f} % of "
        "the non-zero values become 0.",
        f"- Short vs long window of the static groups (two independent Monte Carlo estimates plus motion blur): "
        f"energy-weighted |short - long| / long = {info['mc_difference']:.2f}"
        + (f", {info['mc_difference'] / chosen['energy_error']:.0f} times the default's energy-weighted error."
           if chosen is not None and chosen["energy_error"] > 0 else "."),
        f"- Frame 0 files with the reference option: "
        + ", ".join(f"{k} {v:.1f} MB" for k, v in base["frame0_files_mb"].items()) + ".",
    ]
    if info.get("exrheader"):
        eh = info["exrheader"]
        bad = [k for k, v in eh["ok"].items() if not v]
        lines.append(f"- `exrheader` of OpenEXR {eh['version']} opens every option"
                     + (f" except {', '.join(bad)}" if bad else "") + " (and prints the scale attributes).")
    lines += ["", "## Choice", ""]
    if chosen is None:
        lines.append(f"No allowed option is within {TARGET_MB:g} MB on this scene.")
    else:
        default = next((r for r in results if is_default(r)), None)
        same = default is not None and default["label"] == chosen["label"]
        lines.append(f"Default (`{C.DEFAULT_STORAGE}`): **{chosen['label']}**, the allowed option within "
                     f"{TARGET_MB:g} MB with the smallest energy-weighted error (ties: the smaller files)"
                     + ("" if same else f" -- NOT the storage new corpora get now "
                        f"({default['label'] if default else 'not measured'}): change `lfmbench.corpus.STORAGES`")
                     + f": {chosen['size_mb']:.1f} MB per scene vs "
                     f"{base['size_mb']:.1f} MB ({base['size_mb'] / chosen['size_mb']:.1f}x smaller), "
                     f"energy-weighted error {chosen['energy_error']:.2e} (worst layer "
                     f"{chosen['max_layer_energy_error']:.2e}), at most {chosen['max_value_error']:.2e} per value "
                     f"within 120 dB of the layer peak; decode {chosen['decode_ms_per_frame']:.0f} ms/frame vs "
                     f"{base['decode_ms_per_frame']:.0f}.")
    lines.append("")
    atomic_write_text(path, "\n".join(lines))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--corpus", type=Path, help="corpus holding the scene (float32 storage gives exact errors)")
    ap.add_argument("--scene", help="scene id (default: the first)")
    ap.add_argument("--quick", action="store_true", help="render a small scene if no --corpus; fewer options")
    ap.add_argument("--repeats", type=int, default=None, help="timing repeats (default 3, --quick 1)")
    ap.add_argument("--out", type=Path, default=ROOT / "bench_out" / "storage")
    ap.add_argument("--doc", type=Path, default=ROOT / "docs" / "benchmarks" / "storage.md")
    a = ap.parse_args(argv)
    repeats = a.repeats or (1 if a.quick else 3)
    a.out.mkdir(parents=True, exist_ok=True)
    cpath = a.corpus
    if cpath is None:
        if not a.quick:
            ap.error("give --corpus DIR (e.g. `lfmbench render --out DIR --storage float32`) "
                     "or --quick")
        cpath = a.out / "corpus"
        if not (cpath / C.MANIFEST_NAME).is_file() or not C.Corpus(cpath).scenes:
            import _llvm  # noqa: F401  (DRJIT_LIBLLVM_PATH before Mitsuba loads)
            from render_tools import jobs as J
            opts = J.load_profile("small")
            jobs = J.make_jobs(cpath, n_scenes=1, seed=3, options=opts, dtype="float32")
            J.run_jobs(jobs, C.CorpusWriter(cpath, dtype="float32",
                                            render=J.render_record(3, opts, "float32", {})))
    corpus = C.Corpus(cpath)
    sid = a.scene or corpus.scenes[0]
    scene, meta, frames = load_scene(corpus, sid)
    meta = {k: v for k, v in meta.items() if k != "storage"}
    input_storage = corpus.meta(sid).get("storage", {"dtype": "float32", "compression": "zip"})
    lay = list(layers(frames))
    options = [o for o in FULL if not a.quick or o[0] in QUICK_LABELS]
    results = []
    part_path = a.out / "partial.json"
    key = f"{cpath.resolve()}|{sid}|{repeats}"
    partial = load_json(part_path, "partial results") if part_path.is_file() else {}
    partial = partial if partial.get("key") == key else {"key": key, "results": {}}
    with tempfile.TemporaryDirectory(dir=a.out) as tmp:
        for label, st, _ in options:
            if label in partial["results"]:  # measured by an interrupted earlier run of the same command
                results.append(partial["results"][label])
                continue
            results.append(bench_one(label, st, scene, meta, frames, Path(tmp), repeats))
            partial["results"][label] = results[-1]
            atomic_write_text(part_path, json.dumps(partial, default=str))
        eh = exrheader_check(Path(tmp), results, scene, meta, frames)
    chosen = choose(results)
    info = {"cmd": "`" + " ".join(["python benchmarks/bench_storage.py"] + (argv or sys.argv[1:])) + "`",
            "date": time.strftime("%Y-%m-%d"), "machine": f"{platform.machine()} {platform.processor() or ''}".strip(),
            "corpus": str(cpath), "meta": meta, "render": corpus.manifest.get("render"), "repeats": repeats, "n_layers": len(lay),
            "n_values": sum(x.size for *_, x in lay), "input_storage": input_storage,
            "unscaled_half": unscaled_half_error(frames), "mc_difference": mc_difference(frames), "exrheader": eh}
    atomic_write_text(a.out / "results.json", json.dumps({"info": info, "results": results, "chosen": chosen},
                                                        indent=1, default=str))
    write_doc(a.doc, info, results, chosen)
    print(f"chosen: {chosen['label'] if chosen else None}; wrote {a.doc} and {a.out / 'results.json'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
