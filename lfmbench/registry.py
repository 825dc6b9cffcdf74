"""One way to register things of one kind by name: a :class:`Registry` (decorator + validated lookup).

The ISP stages, the metrics, the baselines, the sensor architectures and the sensor presets each keep one
registry; adding one more is one ``register`` call (or one decorator) beside its definition, and every list of
names (command-line choices and help, error messages) is read from the registry, never typed a second time.

>>> COLOURS = Registry("colour")
>>> @COLOURS.register("red")
... def red():
...     return (1, 0, 0)
>>> COLOURS.register("green", lambda: (0, 1, 0))  # as a call
<function <lambda> at ...>
>>> COLOURS.names(), "red" in COLOURS, COLOURS.get("red")()
(('red', 'green'), True, (1, 0, 0))
>>> COLOURS.get("blue")
Traceback (most recent call last):
...
ValueError: unknown colour 'blue'; valid: red, green

A registry is a read-only ``Mapping`` in registration order (``registry[name]``, ``len``, iteration over the
names), so code that read the plain dicts it replaces reads it unchanged; only :meth:`Registry.get` differs from
``dict.get``: it raises on an unknown name instead of returning ``None``.
"""
from __future__ import annotations

from collections.abc import Iterator, Mapping
from typing import Any, Callable, Generic, TypeVar, overload

from lfmbench.limits import brief

__all__ = ["Registry"]

T = TypeVar("T")


class Registry(Mapping[str, T], Generic[T]):
    """Things of one ``kind`` (a word for messages: ``"metric"``, ``"baseline"``), by name, in registration order.

    Args:
        kind: what the registry holds, named in every error (``unknown metric 'x'; valid: ...``).
    """

    def __init__(self, kind: str) -> None:
        if not isinstance(kind, str) or not kind:
            raise ValueError(f"kind must be a non-empty string, got {brief(kind)}")
        self.kind = kind
        self._items: dict[str, T] = {}

    @overload
    def register(self, name: str) -> Callable[[T], T]: ...

    @overload
    def register(self, name: str, obj: T) -> T: ...

    def register(self, name: str, obj: Any = None) -> Any:
        """Register ``obj`` under ``name``; without ``obj``, a decorator that registers what it decorates.

        Returns ``obj`` (the decorated thing, unchanged). Raises ``ValueError`` for a name that is not a
        non-empty string or that is registered already (one name, one thing: remove the old one first with
        :meth:`unregister`).
        """
        if not isinstance(name, str) or not name:
            raise ValueError(f"{self.kind} name must be a non-empty string, got {brief(name)}")
        if name in self._items:
            raise ValueError(f"{self.kind} {name!r} is registered already")
        if obj is None:
            def decorator(thing: T) -> T:
                self.register(name, thing)
                return thing
            return decorator
        self._items[name] = obj
        return obj

    def unregister(self, name: str) -> T:
        """Remove ``name`` (e.g. a test's toy entry) and return what it held; ``ValueError`` when unknown."""
        thing = self.get(name)
        del self._items[name]
        return thing

    def get(self, name: Any) -> T:  # type: ignore[override]
        """The thing registered as ``name``; a one-line ``ValueError`` listing the valid names otherwise."""
        try:
            return self._items[name]
        except (KeyError, TypeError):
            raise ValueError(f"unknown {self.kind} {brief(name)}; valid: {', '.join(self._items) or '(none)'}") \
                from None

    def names(self) -> tuple[str, ...]:
        """The registered names, in registration order."""
        return tuple(self._items)

    def __getitem__(self, name: str) -> T:
        return self._items[name]

    def __contains__(self, name: object) -> bool:
        try:
            return name in self._items
        except TypeError:  # an unhashable name is simply not registered
            return False

    def __iter__(self) -> Iterator[str]:
        return iter(self._items)

    def __len__(self) -> int:
        return len(self._items)

    def __repr__(self) -> str:
        return f"Registry({self.kind!r}: {', '.join(self._items)})"
