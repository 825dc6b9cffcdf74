"""The batched (on-device) capture path of lfmbench.datasets.batched against the per-sample path.

Tiny generated corpora (``make_corpus`` of tests/datasets/test_datasets.py). Physics against independent answers: dense
time integration of the PWM waveform per row (rolling shutter) and the EMVA 1288 photon transfer (variance
against mean slope = system gain) through the batched path.
"""
from __future__ import annotations

import numpy as np
import pytest
import torch
from torch.utils.data import DataLoader

from lfmbench import corpus as C
from lfmbench.datasets import LFMCaptureDataset
from lfmbench.datasets.batch_compose import compose_batch, pwm_weights
from lfmbench.datasets.batched import BatchedCaptureSimulator, collate_pieces, pieces_to, prefetch, simulate_batch
from lfmbench.datasets.assembly import bin_edges, row_window_starts, visible_lights, window_bin_exposure
from lfmbench.datasets.projection import build_layers
from lfmbench.flicker import pwm_exposure
from lfmbench.sensor import load_preset
from tests.datasets.test_datasets import _brute_force_light, make_corpus

ALL = ("raw", "input_referred", "saturated", "gt", "light_index", "depth", "rgb")


@pytest.fixture(scope="module")
def corpus(tmp_path_factory):
    return make_corpus(tmp_path_factory.mktemp("bcorpus"), n_scenes=2)


@pytest.fixture(scope="module")
def imported(tmp_path_factory):
    groups = {"skymap": {"flicker": False}, "otherlights": {"flicker": True, "bins": 0}}
    return make_corpus(tmp_path_factory.mktemp("bimported"), n_scenes=1, groups=groups)


def _pair(root, **kw):
    kw = {"split": "all", "cache_dir": False, **kw}
    return LFMCaptureDataset(root, **kw), LFMCaptureDataset(root, pieces=True, **kw)


def _batch(ds, idx):
    return collate_pieces([ds[i] for i in idx])


# ----------------------------------------------------------------------------------------------------------
# exact agreement with the per-sample path (CPU)
# ----------------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("shutter", ["global", "rolling"])
def test_pwm_weights_equal_the_per_sample_weights_exactly(corpus, shutter):
    _, ds = _pair(corpus, shutter=shutter, frames=3, crop=(12, 16), samples_per_scene=3)
    idx = list(range(len(ds)))
    batch = _batch(ds, idx)
    wts = pwm_weights(batch)
    c = C.Corpus(corpus)
    s = 0
    n_checked = 0
    for i in idx:
        sid, per_light, _pg, crop, _ns, start = ds.draws(i)
        meta = c.meta(sid)
        tm = meta["timing"]
        t_len = {"lpd": tm["short_exposure_s"], "spd": tm["long_exposure_s"]}
        layers = ds.scene(sid).layers
        rows = np.arange(crop[0], crop[0] + crop[2], dtype=np.float64)
        starts = {f: row_window_starts(meta, f, rows, shutter) for f in range(start, start + 3)}
        for f in range(start, start + 3):
            for _lid, p, _b0, _inter, rates in visible_lights(layers, f, crop, per_light):
                K = int(rates["lpd"].shape[0])
                edges = f / float(meta["fps"]) + bin_edges(tm["capture_window_s"], K)
                for key, pd, level in (("lpd", "lpd", "pwm"), ("spd", "spd", "pwm"), ("gt", "lpd", "mean")):
                    st = starts[f][pd] if shutter == "rolling" else starts[f][pd][:1]
                    ref = window_bin_exposure(edges, st, t_len[pd], p["period_s"], p["duty"], p["phase_s"],
                                              p["rise_s"], p["fall_s"], level, check=False)      # (R, K) s
                    got = wts[key][s, :, :K].numpy()
                    assert np.array_equal(got, ref), (i, f, key)          # bit for bit
                    assert not wts[key][s, :, K:].any()                   # padded bins weigh nothing
                    n_checked += 1
                s += 1
    assert s == batch["slot_K"].shape[0] and n_checked >= 3 * 6


#: Relative tolerance between two summation orders of <= 16 non-negative float32 terms: (16 - 1) eps.
SUM_ORDER_RTOL = 15 * torch.finfo(torch.float32).eps


@pytest.mark.parametrize("shutter", ["global", "rolling"])
def test_batched_outputs_equal_the_per_sample_outputs(corpus, shutter):
    ref_ds, ds = _pair(corpus, shutter=shutter, frames=3, crop=(12, 16), samples_per_scene=3, outputs=ALL)
    out = simulate_batch(_batch(ds, range(len(ds))), ds.preset)
    for i in range(len(ds)):
        ref = ref_ds[i]
        for k, v in ref.items():
            if k == "meta":
                continue
            got = out[k][i]
            assert got.shape == v.shape and got.dtype == v.dtype, k
            if v.is_floating_point():
                # the two paths add a pixel's layers (static groups, light bins x PWM weights: n <= 16 terms in
                # this corpus, all >= 0) in different orders, and the order depends on the CPU's vector width.
                # Two float32 sums of the same n non-negative terms differ by at most (n - 1) eps of the sum
                # (each order errs by <= (n - 1) eps / 2, Higham, "Accuracy and Stability of Numerical
                # Algorithms", 2nd ed., 2002, eq. 4.4): a bound per value, never a count of bit-equal values
                # (depth holds inf where no surface is hit: equal infinities and NaNs count as equal)
                ok = torch.isclose(got, v, rtol=SUM_ORDER_RTOL, atol=0.0, equal_nan=True)
                assert ok.all(), (k, float(((got - v).abs() / v.abs())[~ok].max()))
            else:
                # noise draws come from the same per-sample streams: DN and flags agree (a mean that differed in
                # its last float32 bit could flip a draw; allow one pixel in a thousand)
                assert (got != v).float().mean() <= 1e-3, k
        for k, v in ref["meta"].items():
            got = out["meta"][k][i]
            if torch.is_tensor(v):
                assert torch.equal(got, v), k
            else:
                assert got == v or (torch.is_tensor(got) and got.item() == v), k


@pytest.mark.parametrize("shutter", ["global", "rolling"])
def test_compiled_composition_matches_the_torch_composition(corpus, imported, shutter):
    """compose_batch's compiled CPU pass against its torch form (the one the GPU runs): lights in K bins, rolling
    rows, groups stored without bins (K = 0 slots), a batch without light entries."""
    for root, kw in ((corpus, {"frames": 3, "crop": (12, 16), "samples_per_scene": 3}),
                     (imported, {"samples_per_scene": 2})):
        _, ds = _pair(root, shutter=shutter, **kw)
        batch = _batch(ds, range(len(ds)))
        assert batch["entry_pix"].numel() > 0
        ref = compose_batch(batch, backend="torch")
        got = compose_batch(batch, backend="numba")
        for k in ("lpd", "spd", "gt"):
            assert got[k].shape == ref[k].shape and got[k].dtype == ref[k].dtype
            torch.testing.assert_close(got[k], ref[k], rtol=1e-6, atol=1e-6 * float(ref[k].abs().max()))
        assert not torch.equal(ref["lpd"], ref["gt"])                      # the PWM weights did something
        parallel = compose_batch(batch, backend="numba", threads=3)
        assert all(torch.equal(parallel[k], got[k]) for k in got)           # samples in threads: same result
        perm = torch.randperm(batch["entry_pix"].numel(), generator=torch.Generator().manual_seed(0))
        shuffled = dict(batch, entry_slot=batch["entry_slot"][perm], entry_pix=batch["entry_pix"][perm],
                        entry_values=batch["entry_values"][:, :, perm])     # entries out of sample order
        for k, v in compose_batch(shuffled, backend="numba", threads=3).items():
            torch.testing.assert_close(v, ref[k], rtol=1e-6, atol=1e-6 * float(ref[k].abs().max()))
    empty = {k: (v[:, :, :0] if k == "entry_values" else v[:0]) if k.startswith("entry_") else v
             for k, v in batch.items()}
    for k in ("lpd", "gt"):
        assert torch.equal(compose_batch(empty, backend="numba")[k], compose_batch(empty, backend="torch")[k])
    with pytest.raises(ValueError, match="backend"):
        compose_batch(batch, backend="cuda")


def test_groups_stored_without_bins(imported):
    ref_ds, ds = _pair(imported, noise=False, outputs=("input_referred", "gt"), samples_per_scene=2)
    batch = _batch(ds, [0, 1])
    assert (batch["slot_K"] == 0).all() and batch["slot_K"].numel() == 2 * 3     # one slot per group and frame
    out = simulate_batch(batch, ds.preset)
    for i in range(2):
        ref = ref_ds[i]
        assert ref["meta"]["flicker_mode"] == out["meta"]["flicker_mode"][i] == "per_frame_weight"
        for k in ("gt", "lpd_lcg_e", "spd_e"):
            torch.testing.assert_close(out[k][i], ref[k], rtol=1e-6, atol=1e-3)


@pytest.mark.parametrize("kw", [{"split": "test"}, {"frame_start": "random", "frames": 2}])
def test_frozen_test_split_and_random_frame_start(tmp_path, kw):
    root = make_corpus(tmp_path / "c", n_scenes=5)
    ref_ds, ds = _pair(root, noise=False, outputs=("input_referred", "gt", "depth"), samples_per_scene=2, **kw)
    out = simulate_batch(_batch(ds, range(len(ds))), ds.preset)
    for i in range(len(ds)):
        ref = ref_ds[i]
        assert out["meta"]["frame_start"][i] == ref["meta"]["frame_start"]
        for k in ("gt", "lpd_lcg_e", "spd_e", "depth"):
            torch.testing.assert_close(out[k][i], ref[k], rtol=1e-6, atol=1e-3)


def test_dataloader_with_collate_and_module(corpus):
    _, ds = _pair(corpus, frames=2, crop=8, samples_per_scene=2)
    sim = BatchedCaptureSimulator.from_dataset(ds)
    batches = [sim(pieces_to(b, "cpu")) for b in DataLoader(ds, batch_size=3, collate_fn=collate_pieces)]
    assert [b["lpd_lcg"].shape for b in batches] == [(3, 2, 1, 8, 8), (1, 2, 1, 8, 8)]
    assert batches[0]["light_index"].dtype == torch.int64 and batches[0]["saturated"].shape[2] == 3


def test_collate_in_a_worker_gives_the_same_batch(corpus):
    """In a DataLoader worker collate_pieces allocates the batch in shared memory (its own path); the batch equals
    the one collated in the main process."""
    _, ds = _pair(corpus, frames=2, crop=(12, 16), samples_per_scene=2)
    ref = _batch(ds, range(3))
    got = next(iter(DataLoader(ds, batch_size=3, num_workers=1, collate_fn=collate_pieces)))
    for k, v in ref.items():
        if torch.is_tensor(v):
            assert torch.equal(got[k], v), k


def test_prefetch_keeps_order_raises_and_stops(corpus):
    """prefetch: the same batches in the same order as the loader itself; an error in the producing thread is
    raised at its place in the sequence; leaving early stops the thread."""
    import threading

    _, ds = _pair(corpus, frames=2, crop=(12, 16), samples_per_scene=3)
    loader = DataLoader(ds, batch_size=2, collate_fn=collate_pieces)
    ref, got = list(loader), list(prefetch(loader, depth=2))
    assert len(got) == len(ref) == 3
    for a, b in zip(ref, got):
        assert all(torch.equal(a[k], b[k]) for k in a if torch.is_tensor(a[k]))

    def failing():
        yield 1
        yield 2
        raise KeyError("scene 7")

    seen = []
    with pytest.raises(KeyError, match="scene 7"):
        for x in prefetch(failing()):
            seen.append(x)
    assert seen == [1, 2]
    it = prefetch(iter(range(10 ** 9)))
    assert next(it) == 0
    it.close()                                                              # the consumer leaves early
    assert not [t for t in threading.enumerate() if t.name == "lfmbench-prefetch"]
    with pytest.raises(ValueError, match="depth"):
        next(prefetch([1], depth=0))


# ----------------------------------------------------------------------------------------------------------
# determinism, batch-size independence, statistics
# ----------------------------------------------------------------------------------------------------------
def test_deterministic_per_seed_epoch_index_and_independent_of_batch_size(corpus):
    _, ds = _pair(corpus, frames=2, crop=(12, 16), samples_per_scene=3)
    whole = simulate_batch(_batch(ds, range(6)), ds.preset)
    parts = [simulate_batch(_batch(ds, idx), ds.preset) for idx in ([4, 1], [0], [5, 3, 2])]
    order = [4, 1, 0, 5, 3, 2]
    for k in ("lpd_hcg", "lpd_lcg", "spd", "lpd_lcg_e", "gt", "saturated", "light_index", "depth"):
        got = torch.cat([p[k] for p in parts])
        assert torch.equal(got, whole[k][order]), k                 # bit for bit, whatever the batch
    _, again = _pair(corpus, frames=2, crop=(12, 16), samples_per_scene=3)
    assert torch.equal(simulate_batch(_batch(again, [2]), ds.preset)["lpd_hcg"][0], whole["lpd_hcg"][2])
    again.set_epoch(1)
    assert not torch.equal(simulate_batch(_batch(again, [2]), ds.preset)["lpd_hcg"][0], whole["lpd_hcg"][2])


def test_means_of_every_output_match_with_independent_draws(corpus):
    """Same distributions: per-sample path with seed 1 against the batched path with seed 2 (independent PWM,
    crop and noise draws); |mean difference| < 5 standard errors (from the sample variances, N samples each)."""
    n = 48
    ref_ds = LFMCaptureDataset(corpus, split="all", seed=1, frames=2, crop=(12, 16), samples_per_scene=n // 2,
                               cache_dir=False, outputs=ALL)
    ds = LFMCaptureDataset(corpus, split="all", seed=2, frames=2, crop=(12, 16), samples_per_scene=n // 2,
                           cache_dir=False, outputs=ALL, pieces=True)
    out = simulate_batch(_batch(ds, range(n)), ds.preset)
    ref = [ref_ds[i] for i in range(n)]
    for k in ("lpd_hcg", "lpd_lcg", "spd", "lpd_hcg_e", "lpd_lcg_e", "spd_e", "saturated", "gt", "light_index",
              "depth", "lpd_lcg_rgb", "spd_rgb", "gt_rgb"):
        a = torch.stack([r[k] for r in ref]).double().flatten(1)
        b = out[k].double().flatten(1)
        if k == "depth":   # sky is at infinite depth: compare the finite depths and the share of sky
            assert abs(float(a.isinf().double().mean() - b.isinf().double().mean())) < 0.05
            a, b = a.nan_to_num(posinf=0.0), b.nan_to_num(posinf=0.0)
        a, b = a.mean(1), b.mean(1)                                            # one mean per sample
        se = float(torch.sqrt(a.var() / n + b.var() / n))
        diff = abs(float(a.mean() - b.mean()))
        assert diff <= 5 * se + 1e-9 * abs(float(a.mean())), (k, diff, se)


def _flat_batch(preset, levels_e: np.ndarray, seeds: list[int], size: int = 64, frames: int = 2) -> dict:
    """A pieces batch of flat fields: sample b has LPD mean levels_e[b] e- (short exposure) and the SPD the same
    photo-electrons per its own exposure; no lights."""
    t_s, t_l = 1e-3, 11e-3
    B = len(levels_e)
    rate = torch.as_tensor(levels_e, dtype=torch.float32) / t_s                            # e-/s
    static = rate[:, None, None, None, None].expand(B, frames, 2, size, size).clone()
    static[:, :, 1] *= t_s / t_l                                                            # same e- for the SPD
    return {"static": static, "t0": torch.arange(frames, dtype=torch.float64).expand(B, frames) / 30.0,
            "timing": torch.tensor([[t_s, t_l, 0.0, 0.03]] * B, dtype=torch.float64),
            "crop": torch.tensor([[0, 0, size, size]] * B), "scene_hw": torch.tensor([[size, size]] * B),
            "noise_seed": torch.tensor(seeds), "slot_pwm": torch.zeros(0, 5, dtype=torch.float64),
            "slot_frame": torch.zeros(0, dtype=torch.int64), "slot_K": torch.zeros(0, dtype=torch.int64),
            "slot_sample": torch.zeros(0, dtype=torch.int64), "entry_values": torch.zeros(2, 1, 0),
            "entry_slot": torch.zeros(0, dtype=torch.int32), "entry_pix": torch.zeros(0, dtype=torch.int32),
            "info": {"sensor": preset.name, "frames": frames, "crop_hw": (size, size), "shutter": "global",
                     "noise": True, "outputs": ("raw",)}}


@pytest.mark.parametrize("capture", ["lpd_hcg", "lpd_lcg", "spd"])
def test_photon_transfer_through_the_batched_path(capture):
    """EMVA 1288 photon transfer: temporal variance (half the variance of the difference of a pair, which removes
    PRNU and DSNU) against mean, dark subtracted; the slope is the system gain K (DN/e-) of the preset."""
    preset = load_preset("ovt")
    K = preset.system_gain(capture)
    cap_e = preset.saturation_capacity_e(capture)
    pd = preset.captures[capture].photodiode
    # the photodiode's electrons; SPD inputs are its own e- (levels are given as SPD electrons there)
    levels = np.concatenate([[0.0], np.linspace(0.05, 0.6, 8) * cap_e])
    B = len(levels)
    out = simulate_batch(_flat_batch(preset, np.repeat(levels, 2), list(range(2 * B))), preset)
    y = out[capture].double().reshape(B, 2, -1)                                   # (levels, pair, pixels) DN
    mean = y.mean((1, 2))
    var = 0.5 * (y[:, 0] - y[:, 1]).var(1)
    slope = np.polyfit((mean[1:] - mean[0]).numpy(), (var[1:] - var[0]).numpy(), 1)[0]
    assert abs(slope / K - 1) < 0.05, (capture, pd, slope, K)


# ----------------------------------------------------------------------------------------------------------
# rolling shutter row by row (independent answer: dense time integration)
# ----------------------------------------------------------------------------------------------------------
def test_rolling_shutter_rows_match_dense_time_integration(corpus):
    _, ds = _pair(corpus, shutter="rolling", frames=3, crop=None)
    c = C.Corpus(corpus)
    sid, per_light, _pg, crop, _ns, s0 = ds.draws(1)
    meta = c.meta(sid)
    layers = build_layers(c, sid, load_preset("ovt"), None, 3)
    comp = compose_batch(_batch(ds, [1]))
    tm = meta["timing"]
    ts, tl, td = tm["short_exposure_s"], tm["long_exposure_s"], tm["line_time_s"]
    frame = 1
    rows = sorted({r for _l, _g, box, _r in layers.lights[frame] for r in range(box[0], box[2])})
    checked = 0
    for key, pd, a0, te, level in (("lpd", "lpd", (tl - ts) / 2, ts, "pwm"), ("spd", "spd", 0.0, tl, "pwm"),
                                   ("gt", "lpd", (tl - ts) / 2, ts, "mean")):
        for row in rows[::2] + rows[-1:]:
            a = frame / meta["fps"] + a0 + row * td          # this row's window starts line_time later per row
            expect = layers.static[pd][frame, row].double() * te
            for lid, _g, box, _r in layers.lights[frame]:     # every light crossing the row, integrated densely
                if box[0] <= row < box[2]:
                    bx, e = _brute_force_light(layers, meta, frame, lid, per_light[lid], (a, te), pd, level)
                    expect[bx[1]:bx[3]] += e[row - bx[0]]
            got = comp[key][0, frame, row].double()
            assert (got - expect).abs().max() / expect.abs().max() < 2e-4, (row, key)
            checked += 1
    assert checked > 10
    # and the row delay matters here: the global-shutter composition of the same draws differs on LED rows
    _, glob = _pair(corpus, shutter="global", frames=3, crop=None)
    g = compose_batch(_batch(glob, [1]))
    for key in ("lpd", "spd"):
        assert (g[key] - comp[key]).abs().max() > 1e-4 * comp[key].abs().max(), key


# ----------------------------------------------------------------------------------------------------------
# bad input
# ----------------------------------------------------------------------------------------------------------
def test_bad_batches_are_clear_errors(corpus):
    _, ovt = _pair(corpus, frames=2, crop=8)
    _, imx = _pair(corpus, frames=2, crop=8, sensor="imx490")
    _, three = _pair(corpus, frames=3, crop=8)
    _, rolling = _pair(corpus, frames=2, crop=8, shutter="rolling")
    with pytest.raises(ValueError, match="sensor"):
        collate_pieces([ovt[0], imx[0]])
    with pytest.raises(ValueError, match="frames"):
        collate_pieces([ovt[0], three[0]])
    with pytest.raises(ValueError, match="shutter"):
        collate_pieces([ovt[0], rolling[0]])
    with pytest.raises(ValueError, match="pieces=True"):
        collate_pieces([ovt[0], LFMCaptureDataset(corpus, split="all", frames=2, crop=8, cache_dir=False)[0]])
    with pytest.raises(ValueError, match="empty"):
        collate_pieces([])
    batch = _batch(ovt, [0, 1])
    with pytest.raises(ValueError, match="preset"):
        simulate_batch(batch, "imx490")
    with pytest.raises(ValueError, match="outputs"):
        simulate_batch(batch, "ovt", outputs=("rgb",) if "rgb" not in ovt.outputs else ("nope",))
    bad = dict(batch, entry_values=batch["entry_values"].to("meta"))
    with pytest.raises(ValueError, match=r"batch\['entry_values'\] is on meta.*pieces_to"):
        simulate_batch(bad, "ovt")
    with pytest.raises(ValueError, match="missing"):
        simulate_batch({k: v for k, v in batch.items() if k != "slot_K"}, "ovt")


# ----------------------------------------------------------------------------------------------------------
# CUDA (skips without a GPU)
# ----------------------------------------------------------------------------------------------------------
@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
@pytest.mark.parametrize("shutter", ["global", "rolling"])
def test_cuda_matches_cpu(corpus, shutter):
    _, ds = _pair(corpus, shutter=shutter, frames=3, crop=(12, 16), samples_per_scene=8, outputs=ALL)
    batch = _batch(ds, range(len(ds)))
    cpu_w, gpu_w = pwm_weights(batch), pwm_weights(pieces_to(batch, "cuda"))
    for k in cpu_w:
        torch.testing.assert_close(gpu_w[k].cpu(), cpu_w[k], rtol=1e-12, atol=1e-15)
    cpu_c, gpu_c = compose_batch(batch), compose_batch(pieces_to(batch, "cuda"))
    for k in cpu_c:
        torch.testing.assert_close(gpu_c[k].cpu(), cpu_c[k], rtol=1e-5, atol=1e-6)
    a = simulate_batch(batch, ds.preset)
    b = simulate_batch(pieces_to(batch, "cuda"), ds.preset)
    assert b["lpd_hcg"].device.type == "cuda"
    for k in ("gt", "light_index", "depth"):
        assert torch.allclose(b[k].cpu().double(), a[k].double(), rtol=1e-5, atol=1e-6), k
    n = a["lpd_lcg_e"].numel()
    for k in ("lpd_hcg_e", "lpd_lcg_e", "spd_e"):     # noise: other streams on CUDA, same distribution
        d = (b[k].cpu().double() - a[k].double())
        ref_sd = float((a[k].double() - a["gt"].double()).std()) + 1.0
        assert abs(float(d.mean())) < 6 * ref_sd * np.sqrt(2.0 / n), k


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
@pytest.mark.parametrize("shutter", ["global", "rolling"])
def test_cuda_triton_composition_matches_the_torch_form(corpus, shutter):
    """On CUDA the PWM weights of ideal pulses come from one Triton kernel (the torch form's float64 operations:
    equal), and compose_batch adds the lamp entries with another: the torch form's float32 products, summed over
    the bins and scattered in another order, so equal within float32 rounding of those sums."""
    import warnings

    import lfmbench.datasets.batch_compose as bt

    if bt._COMPOSE_KERNELS.module() is None:
        pytest.skip("Triton is not importable")
    _, ds = _pair(corpus, shutter=shutter, frames=3, crop=(12, 16), samples_per_scene=8, outputs=ALL)
    batch = _batch(ds, range(len(ds)))
    batch["slot_pwm"][:, 3:5] = 0.0                 # ideal pulses (the weights kernel's case)
    batch["info"]["ideal_pulses"] = True
    assert not batch["info"]["group_slots"]
    batch = pieces_to(batch, "cuda")
    assert batch["entry_pix"].shape[0] > 0
    bt._COMPOSE_KERNELS.enabled = False
    try:
        ref_w, ref = pwm_weights(batch), compose_batch(batch, backend="torch")
    finally:
        bt._COMPOSE_KERNELS.enabled = True
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)      # a kernel that fails to compile warns: an error here
        w, out = pwm_weights(batch), compose_batch(batch)
    assert bt._COMPOSE_KERNELS.enabled
    for k in ref_w:     # the same float64 operations in the same order: equal (zeros up to their sign)
        assert torch.equal(w[k], ref_w[k]), k
    for k in ref:
        torch.testing.assert_close(out[k], ref[k], rtol=1e-5, atol=1e-6 * float(ref[k].abs().max()))


def test_gpu_training_example_in_docs_runs(tmp_path):
    """The batched training loop of docs/guide/datasets.md ("Captures on the GPU") runs (on the CPU here)."""
    import re
    from pathlib import Path

    root = make_corpus(tmp_path / "c", n_scenes=2)
    text = (Path(__file__).resolve().parents[2] / "docs" / "guide" / "datasets.md").read_text()
    section = text[text.index("## Captures on the GPU"):]
    code = re.findall(r"```python\n(.*?)```", section, re.S)[0]
    code = (code.replace('"demo_out/corpus"', repr(str(root))).replace("crop=128", "crop=8")
            .replace("range(3)", "range(2)").replace("split=\"train\"", "split=\"all\"")
            .replace("num_workers=2", "num_workers=0").replace(", persistent_workers=True", ""))
    ns: dict = {}
    exec(compile(code, "docs/guide/datasets.md", "exec"), ns)
    assert torch.isfinite(ns["loss"]) and ns["loss"].requires_grad
    assert ns["batch"]["lpd_hcg_e"].shape[1:] == (3, 1, 8, 8) and ns["ds"].epoch == 1


def test_cpu_configuration_example_in_docs_runs(tmp_path):
    """The CPU configuration of docs/guide/datasets.md (one torch thread, simulation threads, prefetch) runs after the
    section's training example and gives the batches of a plain loop."""
    import re
    from pathlib import Path

    root = make_corpus(tmp_path / "c", n_scenes=2)
    text = (Path(__file__).resolve().parents[2] / "docs" / "guide" / "datasets.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text[text.index("## Captures on the GPU"):], re.S)
    setup = (blocks[0].split("net = ")[0].replace('"demo_out/corpus"', repr(str(root))).replace("crop=128", "crop=8")
             .replace("split=\"train\"", "split=\"all\"").replace("num_workers=2", "num_workers=0")
             .replace(", persistent_workers=True", ""))
    cpu = blocks[1].replace("range(3)", "range(1)").replace("shuffle=True", "shuffle=False")
    threads = torch.get_num_threads()
    ns: dict = {}
    try:
        exec(compile(setup + cpu, "docs/guide/datasets.md", "exec"), ns)
    finally:
        torch.set_num_threads(threads)
    ref = simulate_batch(_batch(ns["ds"], range(len(ns["ds"]) - 8, len(ns["ds"]))), ns["ds"].preset)
    assert torch.equal(ns["batch"]["lpd_hcg_e"], ref["lpd_hcg_e"])            # the last batch, bit for bit
