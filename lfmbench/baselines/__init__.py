"""Fusion baselines for LED-flicker mitigation (split pixel and the other capture plans), registered by snake_case
name (:func:`methods_for`: those of one architecture).

A fusion method is any callable ``method(batch: dict) -> Tensor (B, F, 1, H, W)`` in the ``gt`` units
(``docs/guide/contracts.md`` section 3). :data:`REGISTRY` maps the built-in names to callables;
:func:`get_method` also resolves ``package.module:function``. See ``docs/guide/baselines.md``.
"""
from __future__ import annotations

import importlib
from collections.abc import Callable

from lfmbench.baselines import classic, plan_merge
from lfmbench.baselines.checkpoint import lazy_method
from lfmbench.vocabulary import CLASSIC_BASELINES, LEARNED_BASELINES, PLAN_BASELINES, PLAN_LEARNED_BASELINES

Method = Callable[[dict], "object"]


#: Learned baselines: name -> the module that defines the registered method ``name`` (backed by a checkpoint,
#: :func:`lfmbench.baselines.checkpoint.checkpointed_method`) and ``TRAINING`` (how ``lfmbench train --method
#: NAME`` trains it, :class:`lfmbench.baselines.trainable.Trainable`). A new learned baseline is one module and
#: one entry of :data:`lfmbench.vocabulary.LEARNED_BASELINES`.
LEARNED = LEARNED_BASELINES

#: Registered baselines, in leaderboard order: the rule-based ones of :data:`lfmbench.vocabulary.CLASSIC_BASELINES`
#: (functions of :mod:`lfmbench.baselines.classic`), then the learned ones.
REGISTRY: dict[str, Method] = {
    **{name: getattr(classic, name) for name in CLASSIC_BASELINES},
    **{name: lazy_method(module, name) for name, module in LEARNED.items()},
    **{name: getattr(plan_merge, name) for name in PLAN_BASELINES},
}
globals().update({name: REGISTRY[name] for name in (*CLASSIC_BASELINES, *PLAN_BASELINES)})  # lpd_only, ...


def methods_for(architecture: str) -> list[str]:
    """The registered baselines that apply to a sensor architecture, in leaderboard order: the split-pixel ones
    (rule-based and learned) for ``split_pixel``, otherwise the architecture's standard merge and its other
    capture-plan merges (its :data:`lfmbench.sensor.plan.ARCHITECTURES` entry, of :data:`PLAN_BASELINES`) and
    the learned baselines trained per sensor (:data:`PLAN_LEARNED_BASELINES`: the U-Net, whose checkpoint must
    be one trained for that sensor)."""
    from lfmbench.sensor.plan import ARCHITECTURES  # noqa: PLC0415

    if architecture not in ARCHITECTURES:
        raise ValueError(f"architecture must be one of {list(ARCHITECTURES)}, got {architecture!r:.40}")
    if architecture == "split_pixel":
        return [*CLASSIC_BASELINES, *LEARNED]
    arch = ARCHITECTURES[architecture]
    return [arch.baseline, *arch.others, *PLAN_LEARNED_BASELINES]


class MethodNotFoundError(ValueError):
    """A method spec names no registered baseline and no importable ``module:function``."""


def get_method(spec: str | Method) -> Method:
    """Resolve a method spec: a callable, a registered name, or ``package.module:function``.

    Raises:
        MethodNotFoundError: naming the spec and the registered names.
    """
    if callable(spec):
        return spec
    if not isinstance(spec, str) or not spec:
        raise MethodNotFoundError(f"method must be a name or 'package.module:function', got {spec!r}")
    if spec in REGISTRY:
        return REGISTRY[spec]
    if ":" in spec:
        mod_name, _, attr = spec.partition(":")
        try:
            mod = importlib.import_module(mod_name)
        except ImportError as exc:
            raise MethodNotFoundError(f"method {spec!r}: cannot import module {mod_name!r}: {exc}") from exc
        except SystemExit as exc:  # a module that exits on import must not end the caller silently
            raise MethodNotFoundError(f"method {spec!r}: importing module {mod_name!r} called "
                                      f"sys.exit({exc.code!r})") from None
        except Exception as exc:  # noqa: BLE001 - any error while importing user code, named
            raise MethodNotFoundError(f"method {spec!r}: importing module {mod_name!r} failed: "
                                      f"{type(exc).__name__}: {exc}") from exc
        obj = mod
        for part in attr.split("."):
            if not hasattr(obj, part):
                raise MethodNotFoundError(f"method {spec!r}: {mod_name!r} has no attribute {attr!r}")
            obj = getattr(obj, part)
        if not callable(obj):
            raise MethodNotFoundError(f"method {spec!r} is not callable")
        return obj
    raise MethodNotFoundError(f"unknown method {spec!r}; registered: {', '.join(REGISTRY)}; "
                              "or give 'package.module:function'")


__all__ = ["REGISTRY", "LEARNED", "get_method", "methods_for", "MethodNotFoundError", "exposure_select", "exposure_select_bounded", "lpd_only", "spd_only", "upstream_saturated",
           "saturated_exposure_corrected", "flicker_aware", "flicker_aware_two_sided", "temporal"]
