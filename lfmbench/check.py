"""Field and argument checks shared by every reader of user input (one copy, in the style of kornia's
``core/check.py``).

Each check raises ``ValueError`` whose message names the **field** (a dotted path such as
``timing.short_exposure_s`` or ``scene.lights[3].spread_deg``, or an argument name) and, when given, the
**source** (the file or argument the value came from)::

    <source>: field '<field>' must be ..., got <value>

Used by the corpus format (:mod:`lfmbench.corpus`), sensor presets (:mod:`lfmbench.sensor`), PWM
configurations (:mod:`lfmbench.datasets.pwm`), optics (:mod:`lfmbench.sensor.optics`), the flicker model
(:mod:`lfmbench.flicker`, array arguments: :func:`check_array`) and the scene files of ``render_tools``.

Tensor arguments (kornia's ``KORNIA_CHECK_SHAPE`` style): :func:`check_tensor` (type, a shape spec such as
``"B F 1 H W"``, floating dtype, finite values), :func:`check_same_shape`, and for batch dicts
:func:`check_batch_keys` and :func:`check_same_device`; a wrong type raises ``TypeError``, anything else
``ValueError``, each naming the argument.

The scene-id rule (:func:`check_scene_id`) lives here too, so that the corpus writer, the corpus reader and the
scene-file validator accept exactly the same ids.
"""
from __future__ import annotations

import contextlib
import contextvars
import math
import re
from typing import Any, Iterable, Mapping, Sequence

import numpy as np
from lfmbench.limits import brief

__all__ = ["where", "fail", "check_number", "get_number", "check_integer", "check_vector", "check_keys",
           "check_choice", "check_array", "SCENE_ID_PATTERN", "SCENE_ID_MAX_LEN", "scene_id_error",
           "check_scene_id", "torch_device", "value_checks", "trusted_values", "check_tensor", "check_same_shape",
           "check_batch_keys", "check_same_device", "check_int_arg", "check_flag", "check_arg_choice"]

_MISSING = object()

#: Whether value checks that read a tensor's values (finite, non-negative) run; type and shape checks always do.
_VALUE_CHECKS: contextvars.ContextVar[bool] = contextvars.ContextVar("lfmbench_value_checks", default=True)


def value_checks() -> bool:
    """Whether checks of tensor values run here (False inside :func:`trusted_values`)."""
    return _VALUE_CHECKS.get()


@contextlib.contextmanager
def trusted_values():
    """Skip the checks that read tensor values (each one waits for a GPU to finish its queue) for tensors the
    package made itself, e.g. the batched device program's composed electrons (finite and >= 0 by construction).
    Type and shape checks still run."""
    token = _VALUE_CHECKS.set(False)
    try:
        yield
    finally:
        _VALUE_CHECKS.reset(token)


def where(field: str, source: str | None = None) -> str:
    """Prefix of an error message: ``"<source>: field '<field>'"`` (or ``"field '<field>'"`` without source).

    >>> where("fps", "meta.json")
    "meta.json: field 'fps'"
    """
    return f"{source}: field '{field}'" if source else f"field '{field}'"


def fail(field: str, msg: str, source: str | None = None) -> None:
    """Raise ``ValueError(f"{where(field, source)} {msg}")``."""
    raise ValueError(f"{where(field, source)} {msg}")


def _interval(lo: float | None, hi: float | None, lo_open: bool, hi_open: bool) -> str:
    if lo is not None and hi is not None:
        return f"in {'(' if lo_open else '['}{lo}, {hi}{')' if hi_open else ']'}"
    if lo is not None:
        return f"{'>' if lo_open else '>='} {lo}"
    return f"{'<' if hi_open else '<='} {hi}"


def check_number(value: Any, field: str, source: str | None = None, *, lo: float | None = None,
                 hi: float | None = None, lo_open: bool = False, hi_open: bool = False, integer: bool = False,
                 allow_inf: bool = False) -> float | int:
    """A real number (not a bool), finite (``allow_inf``: ``+inf`` allowed), within the bounds.

    Args:
        value: the value to check. field: its name (dotted path). source: the file or argument it came from.
        lo, hi: bounds (None: unbounded); ``lo_open`` / ``hi_open`` exclude them.
        integer: the value must be integral (``2`` and ``2.0`` pass); returned as ``int``.

    Returns:
        ``float(value)`` (``int`` with ``integer=True``).

    >>> check_number(2, "fps", "meta.json", lo=0, lo_open=True)
    2.0
    >>> check_number(0, "fps", "meta.json", lo=0, lo_open=True)
    Traceback (most recent call last):
    ...
    ValueError: meta.json: field 'fps' must be > 0, got 0
    """
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        fail(field, f"must be {'an integer' if integer else 'a number'}, got {brief(value)}", source)
    v = float(value)
    if math.isnan(v) or (math.isinf(v) and not (allow_inf and v > 0)):
        fail(field, f"must be finite, got {brief(value)}", source)
    if integer and not v.is_integer():
        fail(field, f"must be an integer, got {brief(value)}", source)
    if (lo is not None and (v <= lo if lo_open else v < lo)) or (hi is not None and (v >= hi if hi_open else v > hi)):
        fail(field, f"must be {_interval(lo, hi, lo_open, hi_open)}, got {brief(value)}", source)
    return int(v) if integer else v


def get_number(data: Mapping[str, Any], key: str, source: str | None = None, prefix: str = "", *,
               default: Any = _MISSING, **bounds: Any) -> Any:
    """``data[key]`` checked by :func:`check_number` (field name ``prefix + key``); ``default`` when absent,
    an error naming the field when absent without default."""
    if key not in data:
        if default is _MISSING:
            fail(f"{prefix}{key}", "is missing", source)
        return default
    return check_number(data[key], f"{prefix}{key}", source, **bounds)


def check_integer(value: Any, field: str, source: str | None = None, *, lo: int | None = 0,
                  hi: int | None = None) -> int:
    """A JSON integer (``int``, not ``bool``, not ``2.0``) within ``[lo, hi]``."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        fail(field, f"must be an integer, got {brief(value)}", source)
    if (lo is not None and value < lo) or (hi is not None and value > hi):
        fail(field, f"must be an integer {_interval(lo, hi, False, False)}, got {brief(value)}", source)
    return int(value)


def check_vector(value: Any, field: str, source: str | None = None, n: int = 3, *, lo: float | None = None,
                 hi: float | None = None) -> list[float]:
    """A list (or tuple) of ``n`` finite numbers within ``[lo, hi]``; each error names the element."""
    if not isinstance(value, (list, tuple)) or len(value) != n:
        fail(field, f"must be a list of {n} numbers, got {brief(value)}", source)
    # Fast path for the common case (plain finite floats / ints within the bounds: a scene has ~10^5 of them); any
    # other element takes the per-element path below, which names it (the same result, the same errors).
    lo_, hi_ = (-math.inf if lo is None else lo), (math.inf if hi is None else hi)
    out = []
    for x in value:
        t = type(x)
        if not ((t is float or t is int) and lo_ <= x <= hi_ and -math.inf < x < math.inf):
            return [check_number(x, f"{field}[{i}]", source, lo=lo, hi=hi) for i, x in enumerate(value)]
        out.append(float(x))
    return out


def check_keys(data: Any, field: str, source: str | None = None, *, required: Iterable[str] = (),
               optional: Iterable[str] | None = ()) -> Mapping[str, Any]:
    """``data`` is a mapping holding every key of ``required`` and no key outside ``required | optional``
    (``optional=None``: any other key is allowed). Errors name ``field.key``.

    >>> check_keys({"a": 1, "b": 2}, "timing", "x.json", required=["a"])
    Traceback (most recent call last):
    ...
    ValueError: x.json: unknown field 'timing.b' (allowed: ['a'])
    """
    if type(data) is not dict and not isinstance(data, Mapping):  # (a dict first: typing's isinstance is slow)
        fail(field or "(top level)", f"must be an object (mapping), got {type(data).__name__}", source)
    required = tuple(required)
    pre = f"{field}." if field else ""
    if optional is not None:
        allowed = set(required)
        allowed.update(optional)
        unknown = [k for k in data if k not in allowed]
        if unknown:
            unknown = sorted(str(k) for k in unknown)
            names = ", ".join(f"'{pre}{u}'" for u in unknown)
            raise ValueError(f"{source + ': ' if source else ''}unknown field{'s' if len(unknown) > 1 else ''} "
                             f"{names} (allowed: {sorted(allowed)})")
    for k in required:
        if k not in data:
            fail(pre + k, "is missing", source)
    return data


def check_choice(value: Any, field: str, allowed: Sequence[Any], source: str | None = None) -> Any:
    """``value`` is one of ``allowed``."""
    if value not in allowed:
        fail(field, f"must be one of {list(allowed)}, got {brief(value)}", source)
    return value


def check_array(name: str, x: Any, *, lo: float | None = None, hi: float | None = None,
                lo_open: bool = False) -> None:
    """A real scalar, array or tensor argument, finite, every element within ``[lo, hi]``; the message names
    the argument ``name`` and the first bad element (for function arguments, not file fields).

    >>> check_array("duty", [0.5, 1.5], lo=0.0, hi=1.0)
    Traceback (most recent call last):
    ...
    ValueError: duty must be <= 1.0; got 1.5
    """
    if hasattr(x, "detach"):  # torch.Tensor without importing torch here
        x = x.detach().cpu().numpy()
    v = np.asarray(x)
    if v.dtype.kind not in "fiub":
        raise ValueError(f"{name} must be a real number or array, got dtype {v.dtype}")
    if v.dtype.kind == "f" and not np.isfinite(v).all():
        raise ValueError(f"{name} must be finite; got NaN or inf")
    if lo is not None:
        bad = (v <= lo) if lo_open else (v < lo)
        if bad.any():
            raise ValueError(f"{name} must be {'>' if lo_open else '>='} {lo}; got {brief(v[bad].flat[0].item())}")
    if hi is not None and (v > hi).any():
        raise ValueError(f"{name} must be <= {hi}; got {brief(v[v > hi].flat[0].item())}")


# ------------------------------------------------------------------------------------------ function arguments
def check_int_arg(name: str, value: Any, lo: int | None = 0, hi: int | None = None) -> int:
    """An integer argument (not a bool, not ``2.5``) within ``[lo, hi]``; ``TypeError`` for another type,
    ``ValueError`` outside the range, each naming the argument.

    >>> check_int_arg("seed", 1.5)
    Traceback (most recent call last):
    ...
    TypeError: seed must be an integer, got 1.5
    >>> check_int_arg("max_lights", 10 ** 9, 0, 4096)
    Traceback (most recent call last):
    ...
    ValueError: max_lights must be an integer in [0, 4,096], got 1000000000
    """
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise TypeError(f"{name} must be an integer, got {brief(value)}")
    if (lo is not None and value < lo) or (hi is not None and value > hi):
        rng = f">= {lo}" if hi is None else (f"<= {hi:,}" if lo is None else f"in [{lo}, {hi:,}]")
        raise ValueError(f"{name} must be an integer {rng}, got {brief(value)}")
    return int(value)


def check_flag(name: str, value: Any) -> bool:
    """``True`` or ``False`` (numpy's too): ``TypeError`` naming the argument otherwise (``"no"`` is not a flag)."""
    if not isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{name} must be True or False, got {brief(value)}")
    return bool(value)


def check_arg_choice(name: str, value: Any, allowed: Sequence[Any]) -> Any:
    """``value`` is one of ``allowed``: ``ValueError("<name> must be one of (...), got <value>")`` otherwise."""
    try:
        ok = value in allowed
    except TypeError:  # an unhashable value against a set-like ``allowed``
        ok = False
    if not ok:
        raise ValueError(f"{name} must be one of {tuple(allowed)}, got {brief(value)}")
    return value


# ------------------------------------------------------------------------------------------------ tensors
def _shape_ok(shape: tuple[int, ...], tokens: list[str]) -> bool:
    """``shape`` matches the spec ``tokens``: an integer is that size, a name any size, ``*`` zero or more dims."""
    if "*" in tokens:
        k = tokens.index("*")
        head, tail = tokens[:k], tokens[k + 1:]
        if len(shape) < len(head) + len(tail):
            return False
        return _shape_ok(shape[:len(head)], head) and _shape_ok(shape[len(shape) - len(tail):], tail)
    return len(shape) == len(tokens) and all(not t.isdigit() or int(t) == n for t, n in zip(tokens, shape))


def check_tensor(x: Any, name: str, shape: str | None = None, *, what: str | None = None,
                 min_dim: int | None = None, floating: bool = False, finite: bool = False) -> None:
    """A ``torch.Tensor`` argument, checked (in the style of kornia's ``KORNIA_CHECK_SHAPE``).

    Args:
        x: the argument. name: its name, quoted in every message.
        shape: a shape spec, dims separated by spaces: an integer is that size, a name (``B``, ``H``) any size,
            one ``*`` any number of dims (``"* 1 H W"``: a mosaic with any leading dims).
        what: what the tensor is, for the shape message (``"a Bayer mosaic"``: ``raw must be a Bayer mosaic of
            shape (*, 1, H, W), got (2, 3)``).
        min_dim: at least this many dims (``pred must have at least 3 dims (B, ..., H, W), got shape (4,)``;
            with ``shape``, the spec is named in the message).
        floating: the dtype must be floating point. finite: no NaN or inf (skipped inside
            :func:`trusted_values`).

    Raises:
        TypeError: ``x`` is not a tensor. ValueError: the shape, dtype or values are wrong.

    >>> import torch
    >>> check_tensor(torch.zeros(2, 3, 1, 4, 4), "light_index", "B F 1 H W")
    >>> check_tensor(torch.zeros(2, 3, 4, 4), "light_index", "B F 1 H W")
    Traceback (most recent call last):
    ...
    ValueError: light_index must have shape (B, F, 1, H, W), got (2, 3, 4, 4)
    """
    import torch  # noqa: PLC0415 - torch only when a tensor is checked

    if not isinstance(x, torch.Tensor):
        raise TypeError(f"{name} must be a torch.Tensor, got {type(x).__name__}")
    spec = f"({', '.join(shape.split())})" if shape else None
    if min_dim is not None and x.ndim < min_dim:
        raise ValueError(f"{name} must have at least {min_dim} dims{' ' + spec if spec else ''}, got shape "
                         f"{tuple(x.shape)}")
    if shape is not None and not _shape_ok(tuple(x.shape), shape.split()):
        raise ValueError(f"{name} must be {what} of shape {spec}, got {tuple(x.shape)}" if what else
                         f"{name} must have shape {spec}, got {tuple(x.shape)}")
    if floating and not x.is_floating_point():
        raise ValueError(f"{name} must be a floating-point tensor, got {x.dtype}")
    if finite and value_checks() and x.is_floating_point() and x.numel() and not bool(torch.isfinite(x).all()):
        raise ValueError(f"{name} must be finite; got NaN or inf")


def check_same_shape(x: Any, y: Any, x_name: str, y_name: str, *, dtype: bool = False) -> None:
    """Two tensors of one shape (``TypeError`` naming the one that is not a tensor), with ``dtype`` also of one
    dtype::

        pred and gt must have the same shape, got pred (1, 2) and gt (1, 3)
        pred and gt must have the same dtype, got pred torch.float32 and gt torch.float64
    """
    check_tensor(x, x_name)
    check_tensor(y, y_name)
    if x.shape != y.shape:
        raise ValueError(f"{x_name} and {y_name} must have the same shape, got {x_name} {tuple(x.shape)} and "
                         f"{y_name} {tuple(y.shape)}")
    if dtype and x.dtype != y.dtype:
        raise ValueError(f"{x_name} and {y_name} must have the same dtype, got {x_name} {x.dtype} and "
                         f"{y_name} {y.dtype}")


def check_batch_keys(batch: Mapping[str, Any], keys: Iterable[str], name: str = "batch", hint: str = "") -> None:
    """A batch dict holds every key of ``keys``: ``<name>: missing '<key>'; <hint>``."""
    for k in keys:
        if k not in batch:
            raise ValueError(f"{name}: missing {k!r}" + (f"; {hint}" if hint else ""))


def check_same_device(batch: Mapping[str, Any], ref: str, name: str = "batch", hint: str = ""):
    """Every tensor of a batch dict is on the device of ``batch[ref]``; returns that device.

    ``<name>[<key>] is on cuda:0 but <name>[<ref>] is on cpu; <hint>``."""
    import torch  # noqa: PLC0415

    dev = batch[ref].device
    for k, v in batch.items():
        if torch.is_tensor(v) and v.device != dev:
            raise ValueError(f"{name}[{k!r}] is on {v.device} but {name}[{ref!r}] is on {dev}"
                             + (f"; {hint}" if hint else ""))
    return dev


# ------------------------------------------------------------------------------------------------ scene ids
#: The one scene-id rule: ASCII letters, digits, ``_``, ``-``, ``.``, starting with a letter or digit. A scene id
#: is a directory name in a corpus, so it must be a safe, portable file name (no ``/``, ``\``, spaces, ``+``,
#: no leading ``.`` or ``-``).
SCENE_ID_PATTERN = r"[A-Za-z0-9][A-Za-z0-9_.-]*"
#: Longest scene id (characters): a file-name component is limited to 255 bytes on common file systems.
SCENE_ID_MAX_LEN = 255


def scene_id_error(scene_id: Any) -> str | None:
    """Why ``scene_id`` is not a valid scene id, or None.

    >>> scene_id_error("scene00000") is None, scene_id_error("1112201236") is None
    (True, True)
    >>> scene_id_error("a+b")
    "must be letters, digits, '_', '-', '.', starting with a letter or digit, got 'a+b'"
    """
    if not isinstance(scene_id, str) or not re.fullmatch(SCENE_ID_PATTERN, scene_id):
        return f"must be letters, digits, '_', '-', '.', starting with a letter or digit, got {brief(scene_id)}"
    if len(scene_id) > SCENE_ID_MAX_LEN:
        return f"must be at most {SCENE_ID_MAX_LEN} characters, got {len(scene_id)}"
    return None


def check_scene_id(scene_id: Any, field: str = "scene_id", source: str | None = None) -> str:
    """Raise ``ValueError`` naming ``field`` (and ``source``) unless ``scene_id`` is a valid scene id
    (:data:`SCENE_ID_PATTERN`, at most :data:`SCENE_ID_MAX_LEN` characters); returns it."""
    why = scene_id_error(scene_id)
    if why is not None:
        fail(field, why, source)
    return scene_id


def torch_device(name: str, arg: str = "--device"):
    """``torch.device(name)``, checked: a ``ValueError`` naming ``arg`` for a name torch does not know or a CUDA
    device on a machine without CUDA. (torch is imported here, not at module level.)"""
    import torch  # noqa: PLC0415

    try:
        dev = torch.device(name)
    except (RuntimeError, ValueError):
        raise ValueError(f"{arg} must be a torch device such as cpu, cuda or cuda:0, got {brief(name)}") from None
    if dev.type == "cuda" and not torch.cuda.is_available():
        raise ValueError(f"{arg} {name}: CUDA is not available on this machine (use --device cpu)")
    return dev
