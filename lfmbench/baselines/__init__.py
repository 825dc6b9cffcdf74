"""Fusion baselines for LED-flicker mitigation (split pixel and the other capture plans), registered by snake_case
name in one :class:`lfmbench.registry.Registry` (:func:`methods_for`: those of one architecture).

A fusion method is any callable ``method(batch: dict) -> Tensor (B, F, 1, H, W)`` in the ``gt`` units
(``docs/guide/contracts.md`` section 3). :data:`REGISTRY` maps the registered names to callables;
:func:`get_method` also resolves ``package.module:function``. Adding one is one registration beside its
definition: ``@REGISTRY.register("name")`` for a rule (as :mod:`~lfmbench.baselines.classic` does),
:func:`register_learned` for a learned one (a module with the method and its ``TRAINING``). See
``docs/guide/baselines.md`` and ``docs/guide/extending.md``.
"""
from __future__ import annotations

import importlib

from lfmbench.baselines import classic  # registers the split-pixel rules first (leaderboard order)
from lfmbench.baselines.base import LEARNED, PLAN_LEARNED, PLAN_MERGES, REGISTRY, Method
from lfmbench.baselines.checkpoint import lazy_method


def register_learned(name: str, module: str, *, any_plan: bool = False) -> None:
    """Register the learned baseline ``name``: the method ``module.name`` (imported on first use, backed by a
    checkpoint: :func:`lfmbench.baselines.checkpoint.checkpointed_method`) and ``module.TRAINING`` (how
    ``lfmbench train --method NAME`` trains it, :class:`lfmbench.baselines.trainable.Trainable`).

    Args:
        any_plan: the network takes any capture plan (trained per sensor: ``lfmbench train --method NAME
            --sensor PRESET``); otherwise it reads the split pixel's captures only.
    """
    LEARNED.register(name, module)
    if any_plan:
        PLAN_LEARNED.register(name, module)
    REGISTRY.register(name, lazy_method(module, name))


register_learned("learned", "lfmbench.baselines.learned")
register_learned("unet", "lfmbench.baselines.unet", any_plan=True)

from lfmbench.baselines import plan_merge  # noqa: E402 - the capture-plan merges after the learned baselines

from lfmbench.baselines.classic import (flicker_aware, flicker_aware_two_sided, lpd_only,  # noqa: E402
                                        saturated_exposure_corrected, spd_only, temporal, upstream_saturated)
from lfmbench.baselines.plan_merge import exposure_select, exposure_select_bounded  # noqa: E402


def methods_for(architecture: str) -> list[str]:
    """The registered baselines that apply to a sensor architecture, in leaderboard order: the split-pixel ones
    (rule-based and learned) for ``split_pixel``, otherwise the architecture's standard merge and its other
    capture-plan merges (its :data:`lfmbench.sensor.plan.ARCHITECTURES` entry, of :data:`PLAN_MERGES`) and
    the learned baselines trained per sensor (:data:`PLAN_LEARNED`: the U-Net, whose checkpoint must be one
    trained for that sensor). The split-pixel ones are every registered baseline but the capture-plan merges
    (:data:`PLAN_MERGES`), so a rule a user registers is scored with them."""
    from lfmbench.sensor.plan import ARCHITECTURES  # noqa: PLC0415

    if architecture not in ARCHITECTURES:
        raise ValueError(f"architecture must be one of {list(ARCHITECTURES)}, got {architecture!r:.40}")
    if architecture == "split_pixel":
        return [n for n in REGISTRY if n not in PLAN_MERGES]
    arch = ARCHITECTURES[architecture]
    return [arch.baseline, *arch.others, *PLAN_LEARNED]


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


__all__ = ["REGISTRY", "LEARNED", "PLAN_LEARNED", "PLAN_MERGES", "Method", "register_learned", "get_method",
           "methods_for", "MethodNotFoundError", "classic", "plan_merge",
           "lpd_only", "spd_only", "upstream_saturated", "saturated_exposure_corrected", "flicker_aware",
           "flicker_aware_two_sided", "temporal", "exposure_select", "exposure_select_bounded"]
