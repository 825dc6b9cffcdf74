"""Files shipped with the package, addressable by name: configs, sensor presets, ISP pipelines (and, through
:mod:`lfmbench.cli.configs`, the render protocols and profiles of ``render_tools``); and the documentation URL.

A package user has no source tree: ``lfmbench/configs/unet_tiny.yaml`` names nothing in their current folder.
Every option that takes a shipped file therefore takes its *name* (``--config unet_tiny``) as well as a path;
:func:`find_config` resolves one against the installed package (``importlib.resources``), and an unknown name
is an error listing what is installed and where. ``lfmbench configs`` prints the lot.

Documentation pages are not installed with the package: messages and help texts name them by URL
(:func:`docs_url`), which resolves for a package user and a source checkout alike.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

__all__ = ["PROJECT_URL", "DOCS_REF", "docs_url", "ConfigKind", "CONFIG_KINDS", "config_dir", "installed",
           "find_config", "ConfigNotFoundError"]

#: The project's home (``[project.urls]`` of pyproject.toml).
PROJECT_URL = "https://github.com/lfmbench/lfmbench"
#: The branch or tag the documentation URLs point at.
DOCS_REF = "main"


def docs_url(page: str) -> str:
    """URL of a documentation page given relative to ``docs/`` (``"guide/fault-catalogue.md"``), optionally with
    a ``#anchor``; a leading ``docs/`` is accepted.

    >>> docs_url("guide/isp.md")
    'https://github.com/lfmbench/lfmbench/blob/main/docs/guide/isp.md'
    """
    page = page.strip().removeprefix("docs/").lstrip("/")
    return f"{PROJECT_URL}/blob/{DOCS_REF}/docs/{page}"


@dataclass(frozen=True)
class ConfigKind:
    """One kind of shipped configuration file.

    Attributes:
        name: the kind (``"training"``, ``"sensors"`` ...), as ``lfmbench configs`` lists it.
        folder: folder under the ``lfmbench`` package (``"configs/sensors"``).
        what: one line saying what these files are and which option takes them.
        stems: the file stems of this kind in ``folder`` (None: every ``*.yaml`` there).
    """

    name: str
    folder: str
    what: str
    stems: tuple[str, ...] | None = None


#: The kinds of configuration shipped in the ``lfmbench`` package (one entry per kind).
CONFIG_KINDS: dict[str, ConfigKind] = {k.name: k for k in (
    ConfigKind("training", "configs", "training configs of the learned baselines (lfmbench train --config)",
               ("unet", "unet_tiny", "unet_v1", "learned")),
    ConfigKind("sensors", "configs/sensors", "sensor presets (--sensor)"),
    ConfigKind("isp", "configs/isp", "ISP pipelines (evaluate --isp, plot --isp)"),
    ConfigKind("conditions", "configs", "condition bins of the leaderboard breakdown (leaderboard --conditions)",
               ("conditions",)),
    ConfigKind("pwm", "configs", "LED PWM distributions of the dataset (LFMCaptureDataset(pwm=...))", ("pwm",)),
    ConfigKind("demo", "configs", "settings of lfmbench demo", ("demo",)),
)}


class ConfigNotFoundError(ValueError):
    """A config name that is neither an existing file nor a shipped config; the message lists those installed."""


def config_dir(kind: str) -> Path:
    """The installed folder of ``kind`` (a real directory: the package is installed unzipped)."""
    k = CONFIG_KINDS[kind]
    return Path(str(resources.files("lfmbench").joinpath(k.folder)))


def installed(kind: str) -> dict[str, Path]:
    """``{name: path}`` of the shipped configs of ``kind``, sorted by name."""
    k = CONFIG_KINDS[kind]
    d = config_dir(kind)
    found = {p.stem: p for p in d.glob("*.yaml") if p.is_file()} if d.is_dir() else {}
    if k.stems is not None:
        found = {s: found[s] for s in k.stems if s in found}
    return dict(sorted(found.items()))


def find_config(name_or_path: str | os.PathLike, kind: str, option: str = "--config") -> Path:
    """The file a config option names: an existing path as given (whatever it is), else a shipped config of ``kind`` by name
    (``unet_tiny``, ``unet_tiny.yaml`` or the source-tree path ``lfmbench/configs/unet_tiny.yaml`` all find the
    installed file).

    Raises:
        ConfigNotFoundError: neither exists; the message names ``option``, the value, the installed names and
            their folder.
    """
    p = Path(name_or_path)
    if p.exists() or p.is_symlink():  # what is there is the user's (a FIFO or a directory: its reader refuses it)
        return p
    have = installed(kind)
    stem = p.name[: -len(p.suffix)] if p.suffix.lower() in (".yaml", ".yml") else p.name
    # a bare name, or a path inside the source tree's config folder (README lines run outside a checkout)
    bare = len(p.parts) == 1 or p.parent.as_posix().endswith(f"lfmbench/{CONFIG_KINDS[kind].folder}")
    if bare and stem in have:
        return have[stem]
    raise ConfigNotFoundError(
        f"{option} {str(name_or_path)[:200]!r}: no such file, and not a shipped {kind} config; installed: "
        f"{', '.join(have) or 'none'} (in {config_dir(kind)}; `lfmbench configs` lists all)")
