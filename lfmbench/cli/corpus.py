"""Corpus commands of the ``lfmbench`` CLI: ``validate`` and ``import-isetlfm``.

``register(app)`` adds them to the typer app of :mod:`lfmbench.cli`; heavy work is imported in the bodies.
"""
from __future__ import annotations

import json
import warnings
from pathlib import Path
from typing import List, Optional

import typer

__all__ = ["register"]


def validate_cmd(
    corpus: Path = typer.Argument(..., help="Corpus directory (holds manifest.json)."),
    headers_only: bool = typer.Option(False, "--headers-only",
                                      help="Check checksums, files and channels but do not decode pixels."),
    as_json: bool = typer.Option(False, "--json", help="Print the report as JSON."),
    max_errors: int = typer.Option(50, "--max-errors", min=1, help="Errors printed (all are counted)."),
    workers: Optional[int] = typer.Option(None, "--workers", min=1,
                                          help="Processes that check scenes (default: the CPU count, at most 8, "
                                               "for corpora of 2,000 scenes or more)."),
    no_cache: bool = typer.Option(False, "--no-cache",
                                  help="Hash every file and check every scene, even those unchanged since an "
                                       "earlier validate found them clean."),
    cache_file: Optional[Path] = typer.Option(None, "--cache-file",
                                              help="Where validate records what it found (default "
                                                   "CORPUS/.cache/validate.bin; give one for a read-only corpus)."),
) -> None:
    """Check a corpus: missing files, bad SHA-256, wrong/missing channels vs meta.json, NaN/inf/negative
    radiance. Exit status 1 when anything is wrong.

    Files and scenes unchanged since an earlier validate found them clean (same size, mtime, ctime and inode;
    same validator code and limits) are not hashed or checked again; --no-cache checks everything
    (docs/benchmarks/validate.md)."""
    from rich.console import Console

    from lfmbench.cli._common import check_local_paths
    from lfmbench.corpus import validate_corpus
    from lfmbench.progress import Bar

    check_local_paths((("CORPUS", corpus), ("--cache-file", cache_file)))

    console = Console(stderr=True, soft_wrap=True)
    with Bar(None, "validating", "scene", enabled=not as_json, console=console) as prog:
        rep = validate_corpus(corpus, check_pixels=not headers_only, workers=workers, progress=prog.update,
                              cache=False if no_cache else (cache_file or True))
    if as_json:
        typer.echo(json.dumps(rep.to_dict(), indent=1))
    else:
        for w in rep.warnings[:max_errors]:
            console.print(f"[yellow]warning[/]: {w}", highlight=False)
        for e in rep.errors[:max_errors]:
            console.print(f"[red]error[/]: {e}", highlight=False)
        if len(rep.errors) > max_errors:
            console.print(f"... and {len(rep.errors) - max_errors} more errors")
        status = "OK" if rep.ok else f"{len(rep.errors)} error(s)"
        cached = (f" ({rep.cached_scenes} scenes unchanged since an earlier validate found them clean: not checked "
                  "again; --no-cache checks them)" if rep.cached_scenes else "")
        typer.echo(f"{corpus}: {rep.n_scenes} scenes, {rep.n_files} files, {len(rep.warnings)} warning(s): "
                   f"{status}{cached}")
    raise typer.Exit(0 if rep.ok else 1)


def import_isetlfm_cmd(
    src: Path = typer.Argument(..., help="ISET-LFM dataset folder holding <SceneID>/ folders."),
    out: Path = typer.Argument(..., help="Corpus directory to create or extend."),
    scene: Optional[List[str]] = typer.Option(None, "--scene", help="Scene id to import (repeatable; default all)."),
    seed: int = typer.Option(0, "--seed", help="Seed of the train/val/test split."),
    half: bool = typer.Option(False, "--half", help="Store EXR HALF x per-layer 2^e (lossless ZIP; default: "
                                                    "FLOAT, an exact copy; docs/guide/corpus-format.md)."),
    repair: bool = typer.Option(False, "--repair", help="Set NaN/inf/negative radiance to 0 instead of failing."),
    no_resume: bool = typer.Option(False, "--no-resume", help="Re-import scenes that are already complete."),
) -> None:
    """Import the released ISET-LFM dataset (PBRT light-group EXRs + _lf.mat) into the lfmbench corpus format."""
    from rich.console import Console

    from lfmbench.corpus import CorpusError, CorpusWriteError
    from lfmbench.progress import Bar
    from lfmbench.cli._common import check_local_paths
    from lfmbench.corpus.isetlfm import find_scenes, import_isetlfm

    check_local_paths((("SRC", src), ("OUT", out)))

    console = Console(stderr=True, soft_wrap=True)
    # the importer's warnings are in its report, printed below: caught here so that each is printed once (Python
    # printed them too, a second time); any other warning is printed with them
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("default")
        try:
            n = len(scene) if scene else len(find_scenes(src))
            with Bar(n, "importing", "scene", console=console) as prog:
                rep = import_isetlfm(src, out, scenes=list(scene) if scene else None, seed=seed,
                                     dtype="float16" if half else "float32", repair=repair, resume=not no_resume,
                                     progress=lambda sid: prog.advance())
        except (ValueError, CorpusError, CorpusWriteError) as exc:
            for w in dict.fromkeys(str(c.message) for c in caught):
                console.print(f"[yellow]warning[/]: {w}", highlight=False)
            console.print(f"[red]error[/]: {exc}", highlight=False)
            raise typer.Exit(2) from None
    for w in dict.fromkeys([*rep.warnings, *(str(c.message) for c in caught)]):
        console.print(f"[yellow]warning[/]: {w}", highlight=False)
    if rep.repaired:
        console.print(f"repaired {sum(rep.repaired.values())} values in {len(rep.repaired)} files")
    typer.echo(f"{out}: imported {len(rep.imported)} scenes, skipped {len(rep.skipped)} complete ones")


def register(app: typer.Typer) -> None:
    """Add ``validate`` and ``import-isetlfm`` to the ``lfmbench`` app."""
    app.command("validate")(validate_cmd)
    app.command("import-isetlfm")(import_isetlfm_cmd)
