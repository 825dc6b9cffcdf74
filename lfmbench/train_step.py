"""One optimiser step of the training loop (:mod:`lfmbench.train`): Adam (:func:`make_optimizer`), the cosine
learning-rate schedule (:func:`cosine_lr`), the eager step and its CUDA-graph replay (:class:`GraphedStep`,
:data:`CUDA_GRAPH_MODES`), and the loss record read one step late so that the host never waits for the step just
queued on a GPU.
"""
from __future__ import annotations

import math
from typing import Any

import torch

from lfmbench.datasets.batched import tensor_leaves

__all__ = ["CUDA_GRAPH_MODES", "DEAD_FRACTION", "make_optimizer", "GraphedStep", "clip_gradients", "collapse_warning", "cosine_lr"]


#: CUDA graphs of the training step (:class:`GraphedStep`): ``"auto"`` captures the step on CUDA devices, ``"off"``
#: runs every step eagerly.
CUDA_GRAPH_MODES = ("auto", "off")


def make_optimizer(model: torch.nn.Module, cfg: Any, device: torch.device, graph: bool = False) -> torch.optim.Adam:
    """Adam over ``model``'s parameters with ``cfg.train``'s learning rate and weight decay: on the CPU the
    default implementation; on CUDA the fused one, or (``graph``) the capturable one with the learning rate as a
    device tensor, so that a captured step reads the schedule's rate (:class:`GraphedStep`)."""
    t = cfg.train
    if device.type != "cuda":
        return torch.optim.Adam(model.parameters(), lr=t.lr, weight_decay=t.weight_decay)
    if graph:
        return torch.optim.Adam(model.parameters(), lr=torch.tensor(float(t.lr), device=device),
                                weight_decay=t.weight_decay, capturable=True)
    return torch.optim.Adam(model.parameters(), lr=t.lr, weight_decay=t.weight_decay, fused=True)


def _set_lr(opt: torch.optim.Optimizer, lr: float) -> None:
    for g in opt.param_groups:
        if isinstance(g["lr"], torch.Tensor):
            g["lr"].fill_(lr)           # a kernel, no copy from the host: a captured step reads it
        else:
            g["lr"] = lr


def clip_gradients(parameters, grad_clip: float) -> torch.Tensor:
    """Clip the gradients of ``parameters`` to the 2-norm ``grad_clip`` (0: not clipped) and return their 2-norm
    before clipping (a 0-d tensor on their device, not read: no host synchronisation). Unclipped, the gradients
    are scaled by exactly 1 (``clip_grad_norm_`` with an infinite bound)."""
    return torch.nn.utils.clip_grad_norm_(parameters, grad_clip if grad_clip > 0 else float("inf"))


def _eager_step(model, opt, spec, cfg, batch: dict, lr: float):
    """One optimiser step on ``batch``: (loss, terms), both still on the device; the terms also hold
    ``grad_norm``, the gradient's 2-norm before clipping (0 when the network has saturated: :data:`DEAD_FRACTION`)."""
    loss, terms = spec.loss(model, batch, cfg)
    _set_lr(opt, lr)
    opt.zero_grad(set_to_none=True)
    loss.backward()
    norm = clip_gradients(model.parameters(), cfg.train.grad_clip)
    opt.step()
    # detached: a term kept for reading one step late must not keep this step's autograd graph alive
    return loss, {**{k: (v.detach() if isinstance(v, torch.Tensor) else v) for k, v in terms.items()},
                  "grad_norm": norm.detach()}


#: An epoch in which more than this fraction of the steps had a gradient of exactly 0 gets a warning: the network
#: has saturated (blend logits or gain beyond float range) and cannot learn any more (docs/guide/baselines.md,
#: "Training collapse").
DEAD_FRACTION = 0.5


def collapse_warning(zero_steps: int, steps: int, epoch: int) -> str | None:
    """The one-line warning for an epoch (1-based ``epoch``) with ``zero_steps`` of ``steps`` optimiser steps whose
    gradient norm was 0, or None when at most :data:`DEAD_FRACTION` of them were."""
    if steps <= 0 or zero_steps <= DEAD_FRACTION * steps:
        return None
    return (f"warning: epoch {epoch}: the gradient was 0 on {zero_steps} of {steps} steps: the network has "
            "saturated and no longer learns (a training collapse); train again with --no-resume and a larger "
            "train.warmup_steps or a smaller train.lr (docs/guide/baselines.md, 'Training collapse')")


def _stash(loss: torch.Tensor, terms: dict):
    """A step's loss and terms, to be read later without waiting for more than that step: on a GPU one
    asynchronous copy into pinned host memory and an event (``float()`` of a device value would wait for everything
    queued after it too, so the host could never run ahead of the device)."""
    if not loss.is_cuda:
        return loss.detach(), terms
    keys = [k for k, v in terms.items() if isinstance(v, torch.Tensor)]
    vals = torch.stack([loss.detach().double().reshape(())] + [terms[k].detach().double().reshape(()) for k in keys])
    host = torch.empty(vals.shape, dtype=torch.float64, pin_memory=True)
    host.copy_(vals, non_blocking=True)
    done = torch.cuda.Event()
    done.record()
    return (host, done, keys), terms


def _unstash(stashed, terms: dict) -> tuple[float, dict]:
    """(loss, {term: value}) as floats from :func:`_stash`'s record (waits for that step only)."""
    if isinstance(stashed, torch.Tensor):
        return float(stashed), {k: float(v) for k, v in terms.items()}
    host, done, keys = stashed
    done.synchronize()
    vals = host.tolist()
    return vals[0], {**{k: float(v) for k, v in terms.items() if k not in keys}, **dict(zip(keys, vals[1:]))}


class GraphedStep:
    """The training step (loss, backward, gradient clipping, Adam) captured once as a CUDA graph and replayed for
    every batch of the same shapes: the host launches one graph instead of the step's ~1,000 kernels, so it can
    keep ahead of the GPU while it also queues the next batch's simulation.

    The first ``warmup`` steps (and every batch whose tensors differ in shape or dtype from the captured one, such
    as an epoch's last, smaller batch) run eagerly; then the step is captured on the next batch (each batch's
    tensors are copied into the graph's inputs before a replay). The optimiser must be capturable with a tensor
    learning rate (:func:`make_optimizer` with ``graph=True``). Where capturing fails (an operation that cannot be
    captured), one warning names the error and every later step runs eagerly: the same training, slower.

    Call: ``step(batch, lr) -> (loss, terms)``, copies of the graph's outputs (the next replay overwrites them).
    """

    def __init__(self, model, opt, spec, cfg, warmup: int = 3) -> None:
        self.model, self.opt, self.spec, self.cfg, self.warmup = model, opt, spec, cfg, int(warmup)
        self.graph = None
        self.failed = False
        self.eager_steps = 0
        self.replays = 0
        self.sig = None
        self.side = torch.cuda.Stream() if torch.cuda.is_available() else None

    @staticmethod
    def _signature(batch: dict) -> tuple:
        return tuple((path, tuple(t.shape), t.dtype, t.device) for path, t in tensor_leaves(batch))

    def _capture(self, batch: dict) -> None:
        import warnings

        def clone(d: dict) -> dict:
            return {k: (v.clone() if isinstance(v, torch.Tensor) else clone(v) if isinstance(v, dict) else v)
                    for k, v in d.items()}

        static = clone(batch)
        graph = torch.cuda.CUDAGraph()
        self.opt.zero_grad(set_to_none=True)
        try:
            with torch.cuda.graph(graph):
                loss, terms = self.spec.loss(self.model, static, self.cfg)
                loss.backward()
                terms = {**terms, "grad_norm": clip_gradients(self.model.parameters(), self.cfg.train.grad_clip)}
                self.opt.step()
        except Exception as exc:  # noqa: BLE001 - any capture error: train eagerly
            self.failed = True
            first = str(exc).splitlines()[0][:200] if str(exc) else ""
            warnings.warn(f"CUDA graph of the training step: capture failed ({type(exc).__name__}: {first}); "
                          "training without it (--cuda-graph off skips the attempt)", RuntimeWarning, stacklevel=3)
            self.opt.zero_grad(set_to_none=True)
            return
        self.graph, self.static, self.out = graph, static, (loss, terms)
        self.inputs = dict(tensor_leaves(static))

    def __call__(self, batch: dict, lr: float):
        sig = self._signature(batch)
        if self.sig is None:
            self.sig = sig              # the shapes of the first batch: the ones captured
        if sig == self.sig and self.graph is None and not self.failed and self.eager_steps >= self.warmup:
            self._capture(batch)
        if self.graph is None and sig == self.sig and not self.failed:
            # warm-up on a side stream, as capturing a backward pass needs (the autograd engine then runs the
            # leaves' gradient accumulation on a stream the capture may depend on; "CUDA Graphs", PyTorch docs)
            self.eager_steps += 1
            main = torch.cuda.current_stream()
            self.side.wait_stream(main)
            with torch.cuda.stream(self.side):
                out = _eager_step(self.model, self.opt, self.spec, self.cfg, batch, lr)
            main.wait_stream(self.side)
            return out
        if self.graph is None or sig != self.sig:
            return _eager_step(self.model, self.opt, self.spec, self.cfg, batch, lr)
        for path, t in tensor_leaves(batch):
            self.inputs[path].copy_(t, non_blocking=True)
        _set_lr(self.opt, lr)
        self.graph.replay()
        self.replays += 1
        loss, terms = self.out
        return loss.detach().clone(), {k: (v.detach().clone() if isinstance(v, torch.Tensor) else v)
                                       for k, v in terms.items()}


def cosine_lr(step: int, total: int, lr: float, lr_min: float, warmup: int = 0) -> float:
    """Learning rate of optimiser step ``step`` (0-based) of ``total``: cosine from ``lr`` to ``lr_min``
    (Loshchilov & Hutter, "SGDR: Stochastic Gradient Descent with Warm Restarts", ICLR 2017, one cycle), times a
    linear warm-up ``(step + 1) / warmup`` over the first ``warmup`` steps (Goyal et al., "Accurate, Large
    Minibatch SGD: Training ImageNet in 1 Hour", arXiv:1706.02677, 2017, section 2.2).

    Why a warm-up: Adam's per-parameter step is about ``lr`` whatever the gradient's size, while its estimate of the
    gradient's variance still rests on few steps (Liu et al., "On the Variance of the Adaptive Learning Rate and
    Beyond", ICLR 2020); one such step at the full rate can push the U-Net's blend logits and gain into saturation,
    where every gradient is 0 and the network never recovers (docs/guide/baselines.md, "Training collapse")."""
    frac = min(step, total) / max(total, 1)
    cos = lr_min + 0.5 * (lr - lr_min) * (1.0 + math.cos(math.pi * frac))
    return cos * min(1.0, (step + 1) / warmup) if warmup > 0 else cos
