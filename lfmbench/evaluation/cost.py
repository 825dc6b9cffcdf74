"""Cost of a method: wall time per output megapixel, parameters and multiply-accumulates (MACs).

torch is imported by the functions that use it: the leaderboard reads :data:`TIME_MOVED_FACTOR` without it."""
from __future__ import annotations

import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import torch


def method_module(method: Callable) -> torch.nn.Module | None:
    """The ``nn.Module`` behind a method: the method itself, or its ``torch_module`` attribute (a module or a
    zero-argument callable returning one)."""
    import torch  # noqa: PLC0415

    if isinstance(method, torch.nn.Module):
        return method
    mod = getattr(method, "torch_module", None)
    if mod is None:
        return None
    return mod if isinstance(mod, torch.nn.Module) else mod()


def count_params_macs(module: torch.nn.Module, run: Callable[[], Any]) -> tuple[int, int]:
    """(trainable + frozen parameter count, multiply-accumulates of one ``run()``).

    MACs are counted with forward hooks: Conv1d/2d/3d ``out.numel() * in_channels / groups * prod(kernel)``,
    ConvTranspose1d/2d/3d ``in.numel() * out_channels / groups * prod(kernel)`` (every input element scatters a
    kernel-sized patch into each output channel of its group), Linear ``out.numel() * in_features`` (bias and
    activations not counted).
    """
    import torch  # noqa: PLC0415

    macs = 0

    def conv_hook(m, inp, out):
        nonlocal macs
        k = 1
        for s in m.kernel_size:
            k *= s
        macs += out.numel() * (m.in_channels // m.groups) * k

    def tconv_hook(m, inp, out):
        nonlocal macs
        k = 1
        for s in m.kernel_size:
            k *= s
        macs += inp[0].numel() * (m.out_channels // m.groups) * k

    def lin_hook(m, inp, out):
        nonlocal macs
        macs += out.numel() * m.in_features

    hooks = []
    for m in module.modules():
        if isinstance(m, (torch.nn.Conv1d, torch.nn.Conv2d, torch.nn.Conv3d)):
            hooks.append(m.register_forward_hook(conv_hook))
        elif isinstance(m, (torch.nn.ConvTranspose1d, torch.nn.ConvTranspose2d, torch.nn.ConvTranspose3d)):
            hooks.append(m.register_forward_hook(tconv_hook))
        elif isinstance(m, torch.nn.Linear):
            hooks.append(m.register_forward_hook(lin_hook))
    try:
        with torch.no_grad():
            run()
    finally:
        for h in hooks:
            h.remove()
    return sum(p.numel() for p in module.parameters()), int(macs)


def sync(device: torch.device) -> None:
    """Wait for the device (CUDA) to finish queued work; no-op on CPU."""
    if device.type == "cuda":
        import torch  # noqa: PLC0415

        torch.cuda.synchronize(device)


def time_method(method: Callable, batch: dict, warmup: int = 1, repeats: int = 5,
                device: str | torch.device = "cpu") -> list[float]:
    """Wall time (ms) of ``repeats`` calls of ``method(batch)`` (batch tensors (B, F, C, H, W)) after ``warmup``
    calls, synchronised on CUDA."""
    import torch  # noqa: PLC0415

    dev = torch.device(device)
    with torch.no_grad():
        for _ in range(warmup):
            method(dict(batch))
        sync(dev)
        out = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            method(dict(batch))
            sync(dev)
            out.append((time.perf_counter() - t0) * 1e3)
    return out


#: A method's time "moved" when the median of its scored calls (ms per megapixel) lies more than this factor
#: outside the range of its timed calls (:func:`time_moved`).
TIME_MOVED_FACTOR = 2.0


def quartiles(times: list[float]) -> tuple[float, float]:
    """(25th, 75th) percentile of ``times`` (linear interpolation, ``numpy.percentile``'s default)."""
    import numpy as np

    q25, q75 = np.percentile(np.asarray(times, dtype=np.float64), [25, 75])
    return float(q25), float(q75)


def time_moved(timed: list[float], scored: list[float], factor: float = TIME_MOVED_FACTOR) -> bool:
    """Whether a method's run time moved during an evaluation: the median of its ``scored`` calls (one per sample,
    timed while it was scored) lies outside ``[min(timed) / factor, max(timed) * factor]``, the range of its
    ``timed`` calls (the repeated calls after warm-up) widened by ``factor``. Both in the same unit (ms per
    megapixel). A moved time means the machine's load or the method's cost changed between the timing and the
    scoring: its ms/MP is not one a leaderboard can trust.
    """
    import statistics

    if not timed or not scored:
        return False
    m = statistics.median(scored)
    return bool(m < min(timed) / factor or m > max(timed) * factor)
