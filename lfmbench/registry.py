"""A registry of named things of one kind (sensor architectures, presets, baselines, ...): adding one is one entry.

>>> shapes = Registry("shape")
>>> @shapes.register("square")
... def square(x):
...     return x * x
>>> shapes.register("cube", lambda x: x ** 3)
<function <lambda> at ...>
>>> shapes.get("square")(3), "cube" in shapes, shapes.names()
(9, True, ['square', 'cube'])
>>> shapes.get("circle")
Traceback (most recent call last):
ValueError: unknown shape 'circle'; valid choices: ['square', 'cube']
"""
from __future__ import annotations

from typing import Any, Iterator

__all__ = ["Registry"]


class Registry:
    """Named objects of one ``kind``, in registration order.

    ``register(name, obj)`` adds ``obj``; ``register(name)`` returns a decorator that adds the decorated object
    (and returns it unchanged). A name registers once (a second registration raises ``ValueError``).
    ``get(name)`` returns the object or raises a one-line ``ValueError`` naming the valid choices.
    """

    def __init__(self, kind: str) -> None:
        self.kind = str(kind)
        self._items: dict[str, Any] = {}

    def register(self, name: str, obj: Any = None) -> Any:
        """Add ``obj`` under ``name`` (returns ``obj``), or, without ``obj``, a decorator doing so."""
        if not isinstance(name, str) or not name:
            raise ValueError(f"{self.kind} registry: a name must be a non-empty string, got {name!r:.40}")
        if name in self._items:
            raise ValueError(f"{self.kind} registry: {name!r} is already registered")
        if obj is None:
            def deco(o: Any) -> Any:
                self.register(name, o)
                return o
            return deco
        self._items[name] = obj
        return obj

    def get(self, name: str) -> Any:
        """The object registered as ``name``; ``ValueError`` (one line, naming the valid choices) otherwise."""
        try:
            return self._items[name]
        except (KeyError, TypeError):
            raise ValueError(f"unknown {self.kind} {str(name)[:40]!r}; valid choices: {self.names()}") from None

    def names(self) -> list[str]:
        """The registered names in registration order."""
        return list(self._items)

    def __contains__(self, name: object) -> bool:
        return name in self._items

    def __iter__(self) -> Iterator[str]:
        return iter(list(self._items))

    def __len__(self) -> int:
        return len(self._items)

    def __repr__(self) -> str:
        return f"Registry({self.kind!r}, {self.names()})"


