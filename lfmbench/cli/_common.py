"""Checks shared by the commands that run torch (``train``, ``evaluate``): one-line errors, exit status 2."""
from __future__ import annotations

from collections.abc import Callable, Iterable

import typer

__all__ = ["fail", "choice", "lazy", "resolve_lazy", "check_minima", "torch_setup", "lock_output", "check_local_paths"]


#: Placeholder -> the function that makes its text (:func:`lazy`).
_LAZY: dict[str, Callable[[], str]] = {}


def lazy(text: Callable[[], str]) -> str:
    """A placeholder for help text (a help string, a metavar, an epilog) made by ``text()`` only when a command's
    help is shown (:func:`resolve_lazy`): names owned by a registry that imports torch (the baselines, the training
    options) are listed in the help without importing torch at every command's start-up."""
    token = f"{{lazy:{len(_LAZY)}}}"
    _LAZY[token] = text
    return token


def _resolved(s):
    if isinstance(s, str) and "{lazy:" in s:
        for token, text in _LAZY.items():
            if token in s:
                s = s.replace(token, text())
    return s


def resolve_lazy(command) -> None:
    """Replace the :func:`lazy` placeholders of a click ``command`` (its help, epilog, and each parameter's help and
    metavar) by their text: called just before its help is formatted."""
    command.help = _resolved(command.help)
    command.epilog = _resolved(command.epilog)
    for p in getattr(command, "params", ()):
        if getattr(p, "help", None) is not None:
            p.help = _resolved(p.help)
        p.metavar = _resolved(p.metavar)


def choice(names, metavar: str | None = None) -> dict:
    """The keyword arguments of a ``typer.Option`` with a closed list of values owned by a registry or a definition
    (a :class:`lfmbench.registry.Registry`, a mapping's keys or a tuple): the metavar lists them in the help (a
    long list: give a short ``metavar`` and name them in the help text, which wraps), and the parser refuses
    anything else (exit status 2, the option and the names in the message), reading ``names`` when the command
    runs, so an entry added there is listed and accepted without touching the command. ``names`` may be a function
    returning them (an owner that imports torch): called when the value is checked or the help shown (:func:`lazy`)."""
    get = names if callable(names) else (lambda: names)

    def parse(value: str) -> str:
        allowed = [str(n) for n in get()]
        if value not in allowed:
            raise typer.BadParameter(f"{value[:40]!r} is not one of {', '.join(allowed)}")
        return value

    def listed() -> str:
        return f"[{'|'.join(str(n) for n in get())}]"

    return {"parser": parse, "metavar": metavar or (lazy(listed) if callable(names) else listed())}


def fail(msg: str, code: int = 2) -> None:
    """Print ``error: msg`` to stderr and end the command with ``code`` (no traceback). ``msg`` is made one line
    (:func:`lfmbench.limits.one_line`: an error re-raised from a DataLoader worker is its original message)."""
    from lfmbench.limits import one_line  # noqa: PLC0415

    typer.secho(f"error: {one_line(str(msg))}", fg=typer.colors.RED, err=True)
    raise typer.Exit(code)


def check_minima(options: Iterable[tuple[str, int | None, int]]) -> None:
    """``(name, value, lo)`` per integer option: a value given (not None) must be >= lo."""
    for name, v, lo in options:
        if v is not None and v < lo:
            fail(f"{name} must be an integer >= {lo}, got {v}")


def torch_setup(device: str, threads: int | None) -> None:
    """Check ``--threads`` (>= 1; then ``torch.set_num_threads``) and ``--device`` (usable on this machine)."""
    import torch  # noqa: PLC0415 - heavy: only when a command runs

    from lfmbench.check import torch_device  # noqa: PLC0415

    if threads is not None:
        if threads < 1:
            fail(f"--threads must be >= 1, got {threads}")
        torch.set_num_threads(threads)
    try:
        torch_device(device)
    except ValueError as exc:
        fail(str(exc))


def lock_output(ctx: typer.Context, path, option: str) -> None:
    """Take the one-writer lock of the output file ``path`` (:class:`lfmbench.fileio.OutputLock`) for the rest of
    the running command (released when its context ``ctx`` closes, however it ends); another process writing it:
    one line naming ``option`` and the holder, exit 2."""
    from lfmbench.fileio import OutputLock, OutputLockedError  # noqa: PLC0415

    try:
        lock = OutputLock(path, option)
    except OutputLockedError as exc:
        fail(str(exc))
    ctx.call_on_close(lock.release)


def check_local_paths(paths: Iterable[tuple[str, object]]) -> None:
    """``(option name, path or None)`` pairs: a URL-like path (``s3://``, ``gs://``, ``http://``, any
    ``scheme://``) is refused with one line naming the option (:func:`lfmbench.fileio.url_error`)."""
    from lfmbench.fileio import url_error  # noqa: PLC0415

    for name, p in paths:
        why = url_error(name, p)
        if why is not None:
            fail(why)
