"""lfmbench.registry: one way to register things by name (decorator or call, validated lookup)."""
from __future__ import annotations

import pytest

from lfmbench.registry import Registry


def test_decorator_and_call_register_in_order():
    reg: Registry = Registry("widget")

    @reg.register("b")
    def b():
        return "b"

    assert b() == "b"  # the decorator returns what it decorates
    assert reg.register("a", len) is len
    assert reg.names() == ("b", "a") and list(reg) == ["b", "a"] and len(reg) == 2
    assert "a" in reg and "c" not in reg and ["x"] not in reg  # an unhashable name is not registered
    assert reg.get("a") is len and reg["b"] is b and dict(reg) == {"b": b, "a": len}


def test_unknown_name_is_one_line_naming_the_kind_and_the_valid_names():
    reg = Registry("metric")
    reg.register("psnr", object())
    reg.register("ssim", object())
    with pytest.raises(ValueError, match=r"^unknown metric 'nope'; valid: psnr, ssim$"):
        reg.get("nope")
    with pytest.raises(KeyError):  # Mapping item access keeps dict semantics
        reg["nope"]


@pytest.mark.parametrize("name", ["", None, 3])
def test_bad_names_are_refused(name):
    with pytest.raises(ValueError, match="widget name must be a non-empty string"):
        Registry("widget").register(name, object())


def test_a_name_registers_once_and_unregister_frees_it():
    reg = Registry("baseline")
    first, second = object(), object()
    reg.register("x", first)
    with pytest.raises(ValueError, match="baseline 'x' is registered already"):
        reg.register("x", second)
    assert reg.unregister("x") is first and "x" not in reg
    reg.register("x", second)
    assert reg.get("x") is second
    with pytest.raises(ValueError, match="unknown baseline 'y'"):
        reg.unregister("y")
