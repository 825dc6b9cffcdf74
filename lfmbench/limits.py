"""Input limits: the one table of sizes, depths and counts that every reader of user files checks before it
allocates (docs/guide/fault-catalogue.md, "Limits").

A file may claim anything (a 1.9 MB EXR can declare a 6 GB image, a 300-byte YAML file can expand to a billion
nodes, a results file can nest 100,000 arrays): readers compare what a file declares with these limits first
and refuse it with one line naming the file, the limit and how to raise it. The defaults are far above what
lfmbench itself writes (the margins are stated per limit); a user who really needs more raises a limit
explicitly, for one run:

- CLI: ``lfmbench --limit exr_bytes=8e9 validate DIR`` (repeatable, before the command), or
- environment: ``LFMBENCH_LIMITS="exr_bytes=8e9,json_bytes=1e9"`` (also seen by worker processes), or
- Python: ``lfmbench.limits.set_limit("exr_bytes", 8e9)``.

Error messages quote at most :data:`QUOTE_CHARS` characters of a bad value (:func:`brief`).
"""
from __future__ import annotations

import os
import re
import reprlib
from typing import Any

__all__ = ["LIMITS", "LimitError", "limit", "limits_of", "set_limit", "parse_overrides", "brief", "QUOTE_CHARS", "ENV",
           "lights_cap_message", "one_line", "WORKER_DEATH_HINT"]

#: name -> (default, what it bounds and why the default). Bytes are bytes of the file or of decoded pixels.
LIMITS: dict[str, tuple[int, str]] = {
    "json_bytes": (64 << 20, "size of a JSON file other than a manifest (results, meta.json, splits.json, "
                             "test_params.json, ...); a result of the 64-scene v1 test split is < 1 MB"),
    "manifest_bytes": (1 << 30, "size of a corpus manifest.json (about 1 KB per scene: 1 GiB is ~10^6 scenes)"),
    "json_depth": (64, "nesting depth of a JSON document (lfmbench writes at most 6 levels)"),
    "yaml_bytes": (4 << 20, "size of a YAML file (presets, profiles, protocols; the largest shipped is 27 KB)"),
    "yaml_aliases": (100, "YAML aliases (*name) per document; the shipped files use none"),
    "yaml_nodes": (200_000, "YAML nodes per document after alias expansion (the 'billion laughs' bound)"),
    "exr_parts": (4200, "parts of one EXR file: one per light of a group, so MAX_LIGHTS_PER_SCENE plus margin"),
    "exr_channels": (8192, "channels of one EXR part (time bins x bands; 256 bins x 31 bands = 7936)"),
    "exr_side": (65536, "width or height of an EXR display or data window, pixels"),
    "exr_bytes": (4 << 30, "decoded pixel bytes of one EXR file, all parts and channels, as its header declares "
                           "(a 1920x1080 static layer of 2 x 31 FLOAT bands is 514 MB)"),
    "exr_header_bytes": (64 << 20, "bytes of the headers of one EXR file"),
    "exr_frame_bytes": (8 << 30, "decoded pixel bytes of all EXR files of one corpus frame (its groups and aux), "
                                 "as their headers declare, checked before the first of them is decoded: each "
                                 "file is bounded by exr_bytes, a frame of several files was not (a 1920x1080 "
                                 "frame of five static groups of 2 x 31 FLOAT bands is 2.6 GB)"),
    "lights_per_scene": (4096, "lights of one scene (meta.json, scene files, dataset max_lights): every light is "
                               "one EXR part per frame and group, one padded entry per sample and one frozen "
                               "draw per test sample; the busiest rendered scene has 66"),
    "mesh_triangles": (2_000_000, "triangles of all meshes of one scene file (inline or user asset files, counted "
                                  "from what a file declares before its arrays are read; the meshes of a generated "
                                  "lfmbench-v2 scene hold about 1,600)"),
    "mesh_file_bytes": (256 << 20, "size of one user mesh file (OBJ, PLY, glTF/GLB) a scene file references"),
    "psf_radius_px": (256, "optics.psf_radius_px of a sensor preset: the PSF kernel is (2R+1)^2 pixels, convolved "
                           "with every band (the shipped presets use 8)"),
    "psf_samples": (1 << 22, "samples of one band's PSF integration grid, ((2 psf_radius_px + 1) psf_oversample)^2 "
                             "(float64, 32 MiB per band at the limit; the shipped presets use 34,969)"),
    "spectral_file_bytes": (4 << 20, "size of a spectral CSV a sensor preset names (spectral.filters; the shipped "
                                     "one is 25 KB)"),
    "model_parameters": (100_000_000, "parameters of a network a config or checkpoint asks for, counted on "
                                      "torch's meta device before any weight is allocated (the largest shipped "
                                      "U-Net has 1.1 M)"),
    "batch_bytes": (16 << 30, "bytes of the tensors of one training batch: train.batch_size times one sample's "
                              "(its crop, or the whole frame without one, x frames x captures and targets x "
                              "channels x 4 bytes), checked before the first batch is simulated (the shipped "
                              "configs: under 40 MB)"),
    "mat_bytes": (64 << 20, "decoded bytes of the arrays of an imported ISET-LFM .mat file beyond the two (H, W) "
                            "maps its scene's EXR size justifies (MATLAB compresses arrays: a 1 MB file can hold "
                            "1 GB)"),
}

#: Environment variable of explicit overrides: ``name=value`` pairs separated by commas.
ENV = "LFMBENCH_LIMITS"
#: Longest quotation of a bad value in an error message, characters.
QUOTE_CHARS = 80

_overrides: dict[str, int] = {}


class LimitError(ValueError):
    """Input above a limit of :data:`LIMITS`; the message names the file, the limit and how to raise it."""

    def __init__(self, source: str, what: str, value: Any, name: str):
        super().__init__(f"{source}: {what} {value:,} is above the limit {name}={limit(name):,} "
                         f"(raise it with `lfmbench --limit {name}=N ...` or {ENV}=\"{name}=N\" if the file "
                         "is trusted)" if isinstance(value, int) else
                         f"{source}: {what} is above the limit {name}={limit(name):,} (raise it with "
                         f"`lfmbench --limit {name}=N ...` or {ENV}=\"{name}=N\" if the file is trusted)")
        self.name = name


def parse_overrides(text: str, source: str = ENV) -> dict[str, int]:
    """``"a=1,b=2e6"`` -> ``{"a": 1, "b": 2000000}``; ``ValueError`` naming ``source`` for an unknown name or a
    value that is not a positive integer."""
    out = {}
    for item in (t.strip() for t in text.split(",")):
        if not item:
            continue
        name, sep, val = item.partition("=")
        name = name.strip()
        if not sep or name not in LIMITS:
            raise ValueError(f"{source}: {brief(item)} must be NAME=VALUE with NAME one of {', '.join(LIMITS)}")
        try:
            v = float(val)
            if not (v >= 1 and v == int(v)) or v > 2 ** 62:
                raise ValueError
        except (ValueError, OverflowError):
            raise ValueError(f"{source}: {name} must be a positive integer, got {brief(val.strip())}") from None
        out[name] = int(v)
    return out


def limit(name: str) -> int:
    """The current value of limit ``name``: :func:`set_limit`, else :data:`ENV`, else the default."""
    if name in _overrides:
        return _overrides[name]
    env = os.environ.get(ENV)
    if env:
        if _env_seen[0] != env:  # parsed once per value of the variable (readers ask per file)
            try:
                _env_seen[:] = [env, parse_overrides(env)]
            except ValueError:
                _env_seen[:] = [env, {}]  # reported once by the CLI; a bad variable must not break library calls
        v = _env_seen[1].get(name)
        if v is not None:
            return v
    return LIMITS[name][0]


_env_seen: list = [None, {}]  # the last value of ENV and its parsed overrides


def limits_of(*names: str) -> tuple[int, ...]:
    """:func:`limit` of each of ``names``, the environment read once (a reader asks for several per file)."""
    env = os.environ.get(ENV)
    if env and _env_seen[0] != env:
        limit(names[0])
    extra = _env_seen[1] if env else {}
    return tuple(_overrides.get(n, extra.get(n, LIMITS[n][0])) for n in names)


def set_limit(name: str, value: int | None) -> None:
    """Raise (or lower) limit ``name`` for this process; ``None`` restores the default / environment value."""
    if name not in LIMITS:
        raise ValueError(f"limit name must be one of {', '.join(LIMITS)}, got {brief(name)}")
    if value is None:
        _overrides.pop(name, None)
        return
    _overrides.update(parse_overrides(f"{name}={value}", "set_limit"))


def check_batch_bytes(batch_size: int, sample_bytes: int, source: str, detail: str = "") -> None:
    """Refuse (:class:`LimitError` naming ``source`` and ``train.batch_size``) a batch of ``batch_size`` samples of
    ``sample_bytes`` bytes each above the limit ``batch_bytes``, before any of it is allocated. ``detail``: what
    one sample is (crop, frames), for the message."""
    total = int(batch_size) * int(sample_bytes)
    if total > limit("batch_bytes"):
        raise LimitError(source, f"field 'train.batch_size' = {int(batch_size):,} samples of {int(sample_bytes):,} "
                                 f"bytes{' (' + detail + ')' if detail else ''}: a batch of", total, "batch_bytes")


def lights_cap_message(n: int, more: bool = False) -> str:
    """The one message of the per-scene light cap (``lights_per_scene``) for a scene with ``n`` lights (``more``:
    at least ``n``, where a reader stopped counting at the cap)."""
    return (f"has {'more than ' if more else ''}{n:,} lights, above the cap of {limit('lights_per_scene'):,} "
            "lights per scene (each light is an EXR part per frame and group and a frozen draw per test sample; "
            "raise it with `lfmbench --limit lights_per_scene=N` if you mean it)")


def brief(value: Any, n: int | None = None) -> str:
    """``repr(value)`` for an error message, at most ``n`` (default :data:`QUOTE_CHARS`) characters: containers,
    strings and integers are abbreviated before they are turned into text (:mod:`reprlib`), so a huge or deeply
    nested value costs neither time nor memory here.

    >>> brief("x" * 500)[:20], len(brief("x" * 500)) <= QUOTE_CHARS
    ("'xxxxxxxxxxxxxxxxxxx", True)
    >>> brief([1, 2, 3])
    '[1, 2, 3]'
    """
    n = QUOTE_CHARS if n is None else n
    s = _REPR.repr(value)
    return s if len(s) <= n else s[:n - 3] + "..."


class _Brief(reprlib.Repr):
    def repr_int(self, x: int, level: int) -> str:
        if x.bit_length() > 128:  # also: no int-to-text conversion above Python's digit limit
            return f"<an integer of about {int(x.bit_length() * 0.30103) + 1} digits>"
        return super().repr_int(x, level)


_REPR = _Brief()
_REPR.maxlevel, _REPR.maxlist, _REPR.maxtuple, _REPR.maxdict, _REPR.maxset = 3, 8, 8, 6, 8
_REPR.maxstring, _REPR.maxlong, _REPR.maxother = QUOTE_CHARS, 40, QUOTE_CHARS


#: What a user can do when a data-loader worker process died (appended to the one line that says so).
WORKER_DEATH_HINT = ("a data-loader worker process died (the out-of-memory killer or a signal): use fewer --workers "
                     "or a smaller batch or crop, or --workers 0 to see the error in this process")
_WRAPPED = re.compile(r"^Caught (\w+) in (DataLoader worker process \d+|pin memory thread[^.]*)\.", re.M)
_EXC_LINE = re.compile(r"^([A-Za-z_][\w.]*(?:Error|Exception|Warning|Exit|Interrupt)): ?(.*)$")


def one_line(text: str) -> str:
    """The one line a user sees for an error message ``text`` (the ``str`` of an exception).

    - An exception re-raised by a torch ``DataLoader`` from a worker process ("Caught CorpusFileError in DataLoader
      worker process 0. Original Traceback (most recent call last): ...") becomes its original message and where it
      was caught: ``"<original message> (in DataLoader worker process 0)"``; the traceback is dropped (``--debug``
      or ``LFMBENCH_DEBUG=1`` show it).
    - A worker that died ("DataLoader worker (pid 123) is killed by signal: Killed.", "... exited unexpectedly")
      gets :data:`WORKER_DEATH_HINT`.
    - Any other text: its lines joined by " / ".

    >>> one_line("Caught ValueError in DataLoader worker process 1.\\nOriginal Traceback (most recent call last):\\n"
    ...          '  File "x.py", line 3, in f\\n    raise ValueError("a.exr: bad")\\nValueError: a.exr: bad\\n')
    'a.exr: bad (in DataLoader worker process 1)'
    """
    m = _WRAPPED.search(text)
    if m is not None:
        lines = text[m.end():].splitlines()
        for i in range(len(lines) - 1, -1, -1):
            e = _EXC_LINE.match(lines[i])
            if e is not None:
                msg = " ".join([e.group(2), *[ln.strip() for ln in lines[i + 1:] if ln.strip()]]).strip()
                return f"{one_line(msg) if msg else e.group(1)} (in {m.group(2)})"
        return f"{m.group(1)} in {m.group(2)}"
    if "DataLoader worker" in text and ("killed by signal" in text or "exited unexpectedly" in text):
        first = text.strip().splitlines()[0].rstrip(". ") if text.strip() else text
        return f"{first}: {WORKER_DEATH_HINT}"
    return " / ".join(ln.strip() for ln in text.splitlines() if ln.strip())
