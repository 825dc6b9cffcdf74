r"""The composition of a pieces batch (:mod:`lfmbench.datasets.batched`, stage 2), on any device: the exact PWM
weights of every light slot, row and bin (:func:`pwm_weights`) and the mean electrons of both photodiodes and the
ground truth (:func:`compose_batch`), with their Triton (CUDA) and numba (CPU) kernels. The formula is stated in
:mod:`lfmbench.datasets.batched`; every rule is the per-sample path's own (:mod:`lfmbench.datasets.assembly`).
"""
from __future__ import annotations

from typing import Any, Mapping

import numpy as np
import torch

from lfmbench.check import check_batch_keys, check_same_device
from lfmbench.datasets.assembly import bin_edges, window_bin_exposure, window_starts
from lfmbench.datasets.pieces import PWM_FIELDS, gate_table
from lfmbench.datasets.row_gather import gather_rows
from lfmbench.flicker import pwm_exposure
from lfmbench.sensor.fused import map_samples
from lfmbench.triton_kernels import TritonKernels

__all__ = ["pwm_weights", "compose_batch"]

#: Keys of a pieces batch (:func:`collate_pieces`), checked by every function that reads one.
_PIECE_KEYS = ("static", "t0", "timing", "crop", "scene_hw", "noise_seed", "slot_pwm", "slot_frame", "slot_K",
               "slot_sample", "entry_values", "entry_slot", "entry_pix", "info")
_PIECE_HINT = "pass the output of collate_pieces (datasets built with pieces=True)"
_DEVICE_HINT = "move the whole batch with pieces_to(batch, device)"


def pwm_weights(batch: Mapping[str, Any]) -> dict[str, torch.Tensor]:
    """PWM exposure (s) of every slot, row and bin in the LPD and SPD windows, and the ground-truth weights.

    Args:
        batch: from :func:`collate_pieces` (on any one device).

    Returns:
        ``{"lpd", "spd", "gt"}``: (S, R, Kmax) float64 s; R = h rows for a rolling shutter, 1 for a global one
        (row-independent). Bins past a slot's own K weigh 0; a ``K = 0`` slot (a group without bins) has its
        whole-window weight in bin 0. These are the per-sample path's numbers (same functions, same order of
        operations; bit-identical on the CPU). The slots of gated lights (``gate_slot``, ``gate_table``) get
        their waveform's exposure (:meth:`lfmbench.flicker.waveforms.GateTable.exposure`, the per-sample path's
        function, here for all of them at once), under a rolling shutter only on the rows of their boxes
        (:func:`_gate_rows`; 0 on the others, which no entry reads). On CUDA, for a batch of ideal pulses
        without group slots (``info["ideal_pulses"]``, ``info["group_slots"]``), one Triton kernel computes them with the same float64
        operations (:mod:`lfmbench.datasets._compose_triton`; equal, zeros up to their sign); gated slots are then
        computed again by the torch form.
    """
    check_batch_keys(batch, _PIECE_KEYS, hint=_PIECE_HINT)
    dev = check_same_device(batch, "static", hint=_DEVICE_HINT)
    info = batch["info"]
    h = int(info["crop_hw"][0])
    S = int(batch["slot_sample"].shape[0])
    K = batch["slot_K"]
    kmax = int(batch["entry_values"].shape[1])
    gate_slot = batch.get("gate_slot")
    G = 0 if gate_slot is None else int(gate_slot.shape[0])      # (a shape: known on the host)
    out = None
    if (S and info.get("ideal_pulses") and not info.get("group_slots", True)
            and batch["slot_pwm"].dtype == torch.float64 and batch["static"].dtype == torch.float32
            and _COMPOSE_KERNELS.ready(batch["static"])):
        # CUDA: one kernel, the same numbers (lfmbench.datasets._compose_triton)
        R = h if info["shutter"] == "rolling" else 1
        out = _COMPOSE_KERNELS.call("pwm_weights", batch, R, kmax)
        if out is not None and not G:
            return out
    if S == 0:
        z = torch.zeros(0, h if info["shutter"] == "rolling" else 1, kmax, dtype=torch.float64, device=dev)
        return {"lpd": z, "spd": z, "gt": z}
    levels = (("lpd", "lpd", "pwm"), ("spd", "spd", "pwm"), ("gt", "lpd", "mean"))
    if out is None:
        edges, starts, length, pw3 = _slot_windows(batch)
        out = {key: window_bin_exposure(edges, starts[pd], length[pd][:, None, None], pw3["period_s"], pw3["duty"],
                                        pw3["phase_s"], pw3["rise_s"], pw3["fall_s"], level, check=False)
               for key, pd, level in levels}
    if G:
        # gated lights (indicators, strobes, countdowns, destination displays): their waveform's exposure
        gi = gate_slot.long()
        edges, starts, length, pw3 = _slot_windows(batch, gi)                      # of the G gated slots
        tab = gate_table(batch["gate_table"])                                      # fields (G, 1, 1)
        rows = _gate_rows(batch, h)                                                # (G, hb) or None
        if rows is not None:    # rolling: only the rows each gated box covers (the entries read no others)
            starts = {pd: st.gather(1, rows) for pd, st in starts.items()}         # (G, hb) s
        for key, pd, level in levels:
            w = window_bin_exposure(edges, starts[pd], length[pd][:, None, None], pw3["period_s"], pw3["duty"],
                                    pw3["phase_s"], pw3["rise_s"], pw3["fall_s"], level, check=False,
                                    waveform=tab)                                  # (G, R or hb, Kmax) s
            if rows is not None:
                w = torch.zeros((G, h, w.shape[-1]), dtype=w.dtype, device=w.device).scatter_(
                    1, rows[..., None].expand(-1, -1, w.shape[-1]), w)
            out[key][gi] = w
    grp = K == 0
    # (a batch that says it has no group slots skips the test: bool() would wait for the device)
    if info.get("group_slots", True) and bool(grp.any()):
        gi = grp.nonzero()[:, 0]
        _edges, starts, length, pw3 = _slot_windows(batch, gi)
        p = {k: (v[:, :, 0] if torch.is_tensor(v) else v) for k, v in pw3.items()}                # (G, 1)
        for key, pd in (("lpd", "lpd"), ("spd", "spd")):
            wg = pwm_exposure(starts[pd] - p["phase_s"], length[pd][:, None], p["period_s"], p["duty"],
                              rise_time=p["rise_s"], fall_time=p["fall_s"])                    # (G, R) s
            out[key][gi] = 0.0
            out[key][gi, :, 0] = wg
        out["gt"][gi] = 0.0
        out["gt"][gi, :, 0] = (p["duty"] * length["lpd"][:, None]).expand(-1, out["gt"].shape[1])
    return out


def _gate_rows(batch: Mapping[str, Any], h: int) -> torch.Tensor | None:
    """Under a rolling shutter, the crop rows (G, hb) int64 at which to evaluate the G gated slots: row
    ``r0 + j`` of each slot's ``gate_span`` [r0, r1), j < hb (``info["gate_height"]``, the tallest span: a host
    number), the rows past a shorter span repeating its last row (the same numbers written twice, in
    :func:`pwm_weights`'s scatter). None (every row) for a global shutter, a batch without spans, or spans as tall
    as the crop. The weights are an element-wise function of each row's window start, so these rows get the
    numbers the full (G, h, K) computation gives them (what the per-sample path's ``_rolling_bin_exposure`` does
    for plain lamps); the rows outside a span are 0, and no entry of the slot lies there."""
    info = batch["info"]
    span, hb = batch.get("gate_span"), info.get("gate_height")
    if info["shutter"] != "rolling" or span is None or hb is None or not 0 < int(hb) < h:
        return None
    r0 = span[:, 0:1].long()
    last = (span[:, 1:2] - span[:, 0:1] - 1).clamp_min(0).long()                # (G, 1) rows past r0
    j = torch.arange(int(hb), device=span.device, dtype=torch.int64)[None]
    return (r0 + torch.minimum(j, last)).clamp(0, h - 1)


def _slot_windows(batch: Mapping[str, Any], sel: torch.Tensor | None = None) -> tuple:
    """The windows and PWM of the slots ``sel`` ((n,) int64; None: every slot) of a batch: ``(edges, starts,
    length, pw3)``: bin edges (n, Kmax + 1) s (past a slot's K its last edge repeats), window starts pd -> (n, R) s
    (R = h rows for a rolling shutter, else 1), window lengths pd -> (n,) s, the PWM fields (:data:`PWM_FIELDS`)
    -> (n, 1, 1) (ramps the number 0 when ``info["ideal_pulses"]``)."""
    dev, info = batch["static"].device, batch["info"]
    h = int(info["crop_hw"][0])
    kmax = int(batch["entry_values"].shape[1])
    sb, fr, K, pwm = batch["slot_sample"], batch["slot_frame"], batch["slot_K"], batch["slot_pwm"]
    if sel is not None:
        sb, fr, K, pwm = sb[sel], fr[sel], K[sel], pwm[sel]
    n = int(sb.shape[0])
    t_s, t_l, td, cw = batch["timing"][sb].unbind(-1)                              # (n,) s
    t0 = batch["t0"][sb, fr]                                                       # (n,) s
    if info["shutter"] == "rolling":
        rows = batch["crop"][sb, 0:1].to(torch.float64) + torch.arange(h, device=dev, dtype=torch.float64)
        shift = rows * td[:, None]                                                 # (n, h) s
    else:
        shift = torch.zeros(n, 1, dtype=torch.float64, device=dev)
    starts = window_starts(t0[:, None], t_s[:, None], t_l[:, None], shift)        # pd -> (n, R) s
    pw = {k: pwm[:, i] for i, k in enumerate(PWM_FIELDS)}
    if info.get("ideal_pulses"):    # the batch says no slot has ramps: the ideal-pulse formula, decided on the host
        pw["rise_s"] = pw["fall_s"] = 0.0
    pw3 = {k: (v[:, None, None] if torch.is_tensor(v) else v) for k, v in pw.items()}
    edges = t0[:, None] + bin_edges(cw, K.clamp_min(1), like=shift, kmax=kmax)    # (n, Kmax+1) s
    if edges.shape[1] < kmax + 1:
        edges = torch.cat([edges, edges[:, -1:].expand(n, kmax + 1 - edges.shape[1])], 1)
    return edges, starts, {"lpd": t_s, "spd": t_l}, pw3


def compose_batch(batch: Mapping[str, Any], backend: str = "auto", threads: int | None = None) -> dict[str, torch.Tensor]:
    """Mean photo-electrons of every frame of a batch, and the ground truth (the batched :func:`compose_frame`).

    Args:
        batch: from :func:`collate_pieces`, on one device.
        backend: ``"torch"`` (any device), ``"numba"`` (CPU, numba: one pass over the static rates and one
            over the entries, :mod:`lfmbench.datasets._compose_kernel`; the same products, sums in float32 in
            another order, so equal to ``"torch"`` up to float32 rounding) or ``"auto"`` (``"numba"`` on the CPU
            when numba is importable; on CUDA the entries in one Triton kernel,
            :mod:`lfmbench.datasets._compose_triton`, where Triton is importable: also equal to ``"torch"`` up to
            float32 rounding of the sums).
        threads: CPU threads composing samples in parallel (``"numba"`` backend; default
            ``torch.get_num_threads()``; the result does not depend on it).

    Returns:
        ``{"lpd", "spd", "gt"}``: (B, F, h, w) float32 e- (mean, noise-free, unclipped): LPD over the short
        window, SPD over the long one, ``gt`` the LPD with every LED at its duty cycle.
    """
    if backend not in ("auto", "torch", "numba"):
        raise ValueError(f"backend must be 'auto', 'torch' or 'numba', got {backend!r}")
    check_batch_keys(batch, _PIECE_KEYS, hint=_PIECE_HINT)
    dev = check_same_device(batch, "static", hint=_DEVICE_HINT)
    B, F, _, h, w = batch["static"].shape
    t_s, t_l = batch["timing"][:, 0], batch["timing"][:, 1]
    compiled = dev.type == "cpu" and batch["static"].dtype == torch.float32 and _numba_available()
    if backend == "numba" and not compiled:
        raise ValueError("backend='numba' needs a float32 batch on the CPU and numba")
    if compiled and backend != "torch":
        from lfmbench.datasets._compose_kernel import compose

        E = int(batch["entry_pix"].shape[0])
        if E:
            wts = {k: v.float().contiguous() for k, v in pwm_weights(batch).items()}
        else:
            wts = {k: torch.zeros(0, 1, 1, device=dev) for k in ("lpd", "spd", "gt")}
        comp = {k: torch.empty(B, F, h, w, device=dev) for k in ("lpd", "spd", "gt")}
        n = lambda x: x.contiguous().numpy()  # noqa: E731
        args = (n(batch["static"].reshape(B, F, 2, h * w)), n(t_s.float()), n(t_l.float()), n(batch["slot_sample"]),
                n(batch["entry_slot"]), n(batch["entry_pix"]), n(batch["entry_values"]), wts["lpd"].numpy(),
                wts["spd"].numpy(), wts["gt"].numpy(), w, *(comp[k].view(B, F, h * w).numpy()
                                                            for k in ("lpd", "spd", "gt")))
        # one task per sample: its entries are a contiguous run when they come in sample order (as collate_pieces
        # concatenates them); otherwise one task for the whole batch
        ent_sample = args[3][args[4]] if E else np.zeros(0, dtype=np.int64)
        if E and bool((np.diff(ent_sample) < 0).any()):
            compose(*args, 0, B, 0, E)
        else:
            e_at = np.searchsorted(ent_sample, np.arange(B + 1), side="left")
            map_samples(lambda b: compose(*args, b, b + 1, int(e_at[b]), int(e_at[b + 1])), B, threads)
        return comp
    comp = {"lpd": batch["static"][:, :, 0] * t_s.float()[:, None, None, None],
            "spd": batch["static"][:, :, 1] * t_l.float()[:, None, None, None]}
    comp["gt"] = comp["lpd"].clone()
    if int(batch["entry_pix"].shape[0]):
        wts = pwm_weights(batch)
        if (backend != "torch" and batch["entry_values"].dtype == torch.float32
                and _COMPOSE_KERNELS.ready(batch["entry_values"])):
            # None: it failed to compile (before any launch, so ``comp`` holds the static part only): torch below
            if _COMPOSE_KERNELS.call("compose_entries", comp, batch["slot_sample"], batch["entry_slot"],
                                     batch["entry_pix"], batch["entry_values"], wts, h, w) is not None:
                return comp
        slot = batch["entry_slot"].long()
        pix = batch["entry_pix"].long()
        dest = batch["slot_sample"][slot] * (F * h * w) + pix
        R = wts["lpd"].shape[1]
        at = slot * R + (pix % (h * w)) // w if R > 1 else slot                      # (E,) row of (S * R, Kmax)
        vals = batch["entry_values"].transpose(1, 2)                                 # (2, E, Kmax) e-/s
        if vals.stride(-1) != 1:        # entries stored bin-major: make the bins of an entry adjacent
            vals = vals.contiguous()
        kx = wts["lpd"].shape[-1]
        # the three weights of a row in one gather: (S * R, 3, Kmax) -> (E, 3, Kmax) s
        w3 = gather_rows(torch.stack([wts[k].float().reshape(-1, kx) for k in ("lpd", "spd", "gt")], 1), at)
        for j, (key, c) in enumerate((("lpd", 0), ("spd", 1), ("gt", 0))):
            contrib = (vals[c] * w3[:, j]).sum(-1)                                    # (E,) e-
            comp[key].view(-1).index_add_(0, dest, contrib)
    return comp


#: On CUDA, compute the PWM weights and add the lamp entries with Triton kernels
#: (:mod:`lfmbench.datasets._compose_triton`) where Triton is importable (``_COMPOSE_KERNELS.enabled = False``:
#: the torch form everywhere).
_COMPOSE_KERNELS = TritonKernels("lfmbench.datasets._compose_triton", "compose_batch", "the torch composition")


def _numba_available() -> bool:
    """Whether numba is importable (the compiled CPU backends)."""
    from lfmbench.sensor import poisson

    return poisson.available()
