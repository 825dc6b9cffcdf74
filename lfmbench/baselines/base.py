"""The baseline registries (one :class:`lfmbench.registry.Registry` each), apart from the package face so that the
modules defining baselines register them where they are defined.

- :data:`REGISTRY`: every fusion method by name, in leaderboard order (the split-pixel rules of
  :mod:`~lfmbench.baselines.classic`, the learned ones, the capture-plan merges of
  :mod:`~lfmbench.baselines.plan_merge`, then whatever a user registers).
- :data:`PLAN_MERGES`: the rule-based merges of the capture plans other than the split pixel (a subset of
  :data:`REGISTRY`; the architecture registry :data:`lfmbench.sensor.plan.ARCHITECTURES` names each
  architecture's standard one).
- :data:`LEARNED`: learned baselines, name -> the module defining the method ``name`` (backed by a checkpoint) and
  ``TRAINING`` (how ``lfmbench train --method NAME`` trains it); :data:`PLAN_LEARNED`: those whose network takes
  any capture plan (trained per sensor), name -> module.

A fusion method is any callable ``method(batch: dict) -> Tensor (B, F, 1, H, W)`` in the ``gt`` units
(``docs/guide/contracts.md`` section 3).
"""
from __future__ import annotations

from collections.abc import Callable

from lfmbench.registry import Registry

__all__ = ["Method", "REGISTRY", "PLAN_MERGES", "LEARNED", "PLAN_LEARNED", "register_plan_merge"]

Method = Callable[[dict], "object"]

#: Every registered fusion method, name -> callable, in leaderboard order.
REGISTRY: Registry[Method] = Registry("baseline")
#: The rule-based merges of the other capture plans (LOFIC, staggered, chopped, single), name -> callable.
PLAN_MERGES: Registry[Method] = Registry("capture-plan merge")
#: Learned baselines, name -> module (``lfmbench.baselines.register_learned``).
LEARNED: Registry[str] = Registry("learned baseline")
#: The learned baselines whose network takes any capture plan (trained per sensor), name -> module.
PLAN_LEARNED: Registry[str] = Registry("any-plan learned baseline")


def register_plan_merge(fn: Method) -> Method:
    """Decorator: register a capture-plan merge under its function name (in :data:`REGISTRY` and
    :data:`PLAN_MERGES`)."""
    REGISTRY.register(fn.__name__, fn)
    return PLAN_MERGES.register(fn.__name__, fn)
