"""Counter-based random numbers as tensors: SplitMix64 streams, the same bits on every device and batch size.

A draw is a pure function of a 64-bit key and a counter, so a batch of samples draws all its random numbers in a
few element-wise tensor operations (no generator object per sample, no host synchronisation), and any sample's
numbers are the same whether it is drawn alone or in a batch of any size, on the CPU or on a GPU.

The generator is SplitMix64 [Steele2014]_: the state advances by the golden-ratio increment :data:`GAMMA` and
each state is hashed by the variant-13 finaliser (:func:`mix64`). Draw ``j`` (j = 0, 1, ...) of the stream with key
``k`` is ``mix64(k + (j + 1) GAMMA)``, a uniform in (0, 1) takes its top 53 bits (:func:`uniforms`). This is the
stream of the compiled Poisson sampler :mod:`lfmbench.sensor.poisson` (pixel ``i`` of a call seeded ``s`` reads
the stream with key ``mix64(s) + i STRIDE``), whose numba kernel takes its constants from here.

Tensors hold the 64-bit words as ``torch.int64`` bit patterns: addition and multiplication wrap modulo 2^64 as
unsigned arithmetic does (two's complement), exclusive-or is the same, and the logical right shift that int64
lacks is an arithmetic shift followed by a mask (:func:`_shr`).

Functions
- :func:`mix64` -> the SplitMix64 finaliser of int64 words.
- :func:`derive_key` -> one stream key from several words (seed, epoch, sample index, purpose).
- :func:`uniforms` -> (..., n) float64 uniforms in (0, 1) of the streams with the given keys.
- :func:`uniform_at` -> draw ``j`` of each stream, same shape as the keys.

References
----------
.. [Steele2014] G. L. Steele, D. Lea, C. H. Flood, "Fast splittable pseudorandom number generators",
   OOPSLA 2014, https://doi.org/10.1145/2660193.2660195 (SplitMix64; the variant-13 finaliser constants are
   D. Stafford's, "Better bit mixing", 2011).
"""
from __future__ import annotations

import torch

__all__ = ["GAMMA", "STRIDE_LOG2", "MIX_MUL", "mix64", "derive_key", "uniform_at", "uniforms"]

#: SplitMix64 increment: the odd integer closest to 2^64 / golden ratio.
GAMMA = 0x9E3779B97F4A7C15
#: Pixel streams of the Poisson sampler start 2^STRIDE_LOG2 draws apart (a draw uses at most a few dozen).
STRIDE_LOG2 = 20
#: Multipliers of the variant-13 finaliser (Stafford's mix13).
MIX_MUL = (0xBF58476D1CE4E5B9, 0x94D049BB133111EB)
_MASK64 = (1 << 64) - 1


def _signed(c: int) -> int:
    """The int64 whose bit pattern is the unsigned 64-bit ``c``."""
    c &= _MASK64
    return c - (1 << 64) if c >= 1 << 63 else c


_GAMMA_S = _signed(GAMMA)
_MUL_S = tuple(_signed(m) for m in MIX_MUL)


def _shr(z: torch.Tensor, s: int) -> torch.Tensor:
    """Logical right shift of int64 bit patterns by ``s`` (1 <= s <= 63) bits."""
    return (z >> s) & ((1 << (64 - s)) - 1)


def _as_words(x, like: torch.Tensor | None = None) -> torch.Tensor:
    if isinstance(x, torch.Tensor):
        if x.dtype != torch.int64:
            raise TypeError(f"counter_rng: words must be int64 tensors, got {x.dtype}")
        return x
    # a fill on the device, not a copy from the host (a copy would wait for the device's queue)
    return torch.full((), _signed(int(x)), dtype=torch.int64, device=None if like is None else like.device)


def mix64(z: torch.Tensor) -> torch.Tensor:
    """SplitMix64's variant-13 finaliser, element-wise.

    Args:
        z: (*) int64 tensor of 64-bit words (bit patterns), any device.

    Returns:
        (*) int64 tensor, ``z ^= z >> 30; z *= 0xBF58476D1CE4E5B9; z ^= z >> 27; z *= 0x94D049BB133111EB;
        z ^= z >> 31`` in unsigned 64-bit arithmetic.

    >>> s, out = 1234567, []                       # published SplitMix64 outputs for seed 1234567
    >>> for _ in range(2):
    ...     s += GAMMA
    ...     out.append(int(mix64(torch.tensor(_signed(s)))) & _MASK64)
    >>> out
    [6457827717110365317, 3203168211198807973]
    """
    z = (z ^ _shr(z, 30)) * _MUL_S[0]
    z = (z ^ _shr(z, 27)) * _MUL_S[1]
    return z ^ _shr(z, 31)


def derive_key(*words) -> torch.Tensor:
    """One stream key from several 64-bit words, folded in order: ``k = mix64((k ^ w) + GAMMA)`` from ``k = 0``.

    Args:
        words: Python ints (taken modulo 2^64) or int64 tensors (broadcast together), e.g. ``(seed, epoch,
            index_tensor, purpose)``.

    Returns:
        int64 tensor of the broadcast shape of the tensor words (a 0-d tensor when all words are ints), on the
        device of the first tensor word.
    """
    like = next((w for w in words if isinstance(w, torch.Tensor)), None)
    k = torch.zeros((), dtype=torch.int64, device=None if like is None else like.device)
    for w in words:
        k = mix64((k ^ _as_words(w, like)) + _GAMMA_S)
    return k


def uniforms(key: torch.Tensor, n: int, start: int = 0) -> torch.Tensor:
    """Draws ``start .. start + n - 1`` of the SplitMix64 streams with the given keys, as uniforms in (0, 1).

    Draw ``j`` is ``(mix64(key + (j + 1) GAMMA) >> 11 + 0.5) / 2^53``: 53 random bits, never 0 or 1.

    Args:
        key: (*) int64 stream keys (:func:`derive_key`), any device.
        n: number of draws per stream (>= 0). start: index of the first draw.

    Returns:
        (*, n) float64 tensor on ``key``'s device; element ``[..., j]`` depends only on the key and ``start + j``.
    """
    if isinstance(n, bool) or not isinstance(n, int) or n < 0:
        raise ValueError(f"n must be an integer >= 0, got {n!r}")
    if isinstance(start, bool) or not isinstance(start, int) or start < 0:
        raise ValueError(f"start must be an integer >= 0, got {start!r}")
    j = torch.arange(start + 1, start + n + 1, dtype=torch.int64, device=key.device)
    return _to_unit(mix64(key.unsqueeze(-1) + j * _GAMMA_S))


def uniform_at(key: torch.Tensor, j: int) -> torch.Tensor:
    """Draw ``j`` (>= 0) of the streams with keys ``key`` ((*) int64): (*) float64 in (0, 1), element for element
    ``uniforms(key, 1, start=j)[..., 0]``."""
    return _to_unit(mix64(key + _signed((j + 1) * GAMMA)))


def _to_unit(z: torch.Tensor) -> torch.Tensor:
    """The top 53 bits of 64-bit words as a float64 in (0, 1): ``(z >> 11 + 0.5) / 2^53``."""
    return (_shr(z, 11).to(torch.float64) + 0.5) * (1.0 / 9007199254740992.0)
