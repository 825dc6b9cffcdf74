"""The device path (lfmbench.datasets.device) on the CPU: the same pieces and captures as the DataLoader paths,
deterministic across batch sizes, a split that does not fit refused before anything is copied."""
from __future__ import annotations

import pytest
import torch

from lfmbench.datasets import LFMCaptureDataset, collate_pieces, simulate_batch
from lfmbench.datasets.device import DeviceBatches, ResidentMemoryError, ResidentScenes, epoch_order
from lfmbench.datasets.pieces import capture_pieces

OUTS = ("raw", "input_referred", "saturated", "gt", "light_index", "depth")
#: (n - 1) eps of float32 sums of n <= 16 non-negative terms in two orders (tests/datasets/test_batched_capture.py)
SUM_ORDER_RTOL = 15 * torch.finfo(torch.float32).eps


def _assert_outputs_match(batch, j, want, label) -> None:
    """Sample ``j`` of a device batch against a per-sample sample ``want`` (every output but ``meta``): shapes and
    dtypes equal; floats within the summation-order bound; integers (DN, flags) identical but for at most 1 value
    in 1,000 (a composed mean that differs in its last bit can move a noise draw or a DN rounding)."""
    for k, v in want.items():
        if k == "meta":
            continue
        got = batch[k][j]
        assert got.shape == v.shape and got.dtype == v.dtype, (label, k)
        if v.is_floating_point():
            ok = torch.isclose(got, v, rtol=SUM_ORDER_RTOL, atol=0.0, equal_nan=True)
            assert ok.double().mean() >= 0.999, (label, k, float(ok.double().mean()))
        else:
            assert (got != v).double().mean() <= 1e-3, (label, k)


def _ds(root, **kw):
    return LFMCaptureDataset(root, split="all", frames=3, crop=(12, 16), samples_per_scene=3, outputs=OUTS, **kw)


def test_resident_pieces_equal_the_host_pieces(corpus):
    ds = _ds(corpus)
    res = ResidentScenes(ds, "cpu")
    for i in range(len(ds)):
        sid, pl, pg, crop, ns, start = ds.draws(i)
        host = capture_pieces(ds, sid, pl, pg, crop, ns, i, start)
        dev = capture_pieces(ds, sid, pl, pg, crop, ns, i, start, resident=res)
        assert set(host) == set(dev)
        for k, v in host.items():
            if torch.is_tensor(v):
                assert v.dtype == dev[k].dtype and torch.equal(v, dev[k]), (i, k)
    assert res.program is not None and res.bytes == ResidentScenes.estimate(ds)
    # packed: entries padded to the split's most bins plus 12 bytes of coordinates each
    assert ResidentScenes.estimate(ds, packed=False) == sum(ResidentScenes.estimate_scene(ds, s)
                                                            for s in dict.fromkeys(ds.scene_ids))


def test_device_batches_equal_the_per_sample_path_with_counter_noise(corpus):
    """A DeviceBatches batch against the per-sample path (noise_streams="counter") sample for sample: draws, meta
    and integer outputs identical; floats within the summation-order bound; noise from the same streams."""
    ref = _ds(corpus, noise_streams="counter")
    db = DeviceBatches(_ds(corpus), batch_size=4, device="cpu", seed=5)
    db.set_epoch(2)
    ref.set_epoch(2)
    order = epoch_order(len(ref), 5, 2).tolist()
    seen = 0
    for b, batch in enumerate(db):
        for j, i in enumerate(order[4 * b:4 * b + 4]):
            want = ref[i]
            assert batch["meta"]["scene_id"][j] == want["meta"]["scene_id"]
            _assert_outputs_match(batch, j, want, "default")
            seen += 1
    assert seen == len(ref)


@pytest.fixture(scope="module")
def long_corpus(tmp_path_factory):
    """3 scenes of 6 frames: room for random window starts."""
    from tests.data.corpus.data import make_corpus

    return make_corpus(tmp_path_factory.mktemp("long"), frames=6)


_CASES = {
    "default": {},
    "random-start-rolling": dict(frame_start="random", shutter="rolling"),
    "test-split-frozen": dict(split="test", frame_start="random"),
    "sync-group-other-dists": dict(pwm={"sync": "group", "frequency_hz": {"dist": "loguniform", "low": 90, "high": 480},
                                        "duty": {"dist": "choice", "values": [0.1, 0.25, 0.5]},
                                        "rise_time_s": {"dist": "uniform", "low": 0.0, "high": 1e-4}}),
    "full-frame": dict(crop=None),
}


def _program_against_the_per_sample_path(root, kw, label) -> DeviceBatches:
    """Every batch of DeviceBatches on ``root`` (SplitProgram, epoch 4) against the per-sample path with counter
    streams, sample for sample: every meta field (the draws: PWM per light, crop, first frame, epoch, index)
    identical, integer outputs identical but for noise draws moved by a last-bit change, floats within the
    summation bound. Returns the DeviceBatches."""
    ref = LFMCaptureDataset(root, noise_streams="counter", **kw)
    db = DeviceBatches(LFMCaptureDataset(root, **kw), batch_size=5, device="cpu", seed=3)
    assert db.resident.program is not None
    db.set_epoch(4)
    ref.set_epoch(4)
    order = epoch_order(len(ref), 3, 4).tolist()
    for b, batch in enumerate(db):
        for j, i in enumerate(order[5 * b:5 * b + 5]):
            want = ref[i]
            for k, v in want["meta"].items():
                got = batch["meta"][k][j]
                if torch.is_tensor(got):   # (default_collate makes float64 of Python floats)
                    v = v if torch.is_tensor(v) else torch.tensor(v, dtype=got.dtype)
                    assert got.dtype == v.dtype and torch.equal(got, v), (label, i, k, got, v)
                else:
                    assert got == v, (label, i, k)
            _assert_outputs_match(batch, j, want, label)
    return db


@pytest.mark.parametrize("case", sorted(_CASES))
def test_the_batched_program_gives_the_per_sample_draws_and_captures(long_corpus, case):
    """SplitProgram (one batched program, no Python per sample) against the per-sample path with counter streams,
    sample for sample (:func:`_program_against_the_per_sample_path`)."""
    kw = dict(split="all", frames=3, crop=(12, 16), samples_per_scene=3, outputs=OUTS, seed=7)
    kw.update(_CASES[case])
    if kw["split"] == "test":
        kw["samples_per_scene"] = 5
    _program_against_the_per_sample_path(long_corpus, kw, case)


@pytest.fixture(scope="module")
def v2_corpus(tmp_path_factory):
    """3 scenes of 4 frames: 2 with every light kind of scene version 2 (tests.data.corpus.data.V2_LIGHTS:
    indicator, strobe, countdown, destination display, message-sign rows, shared drivers), 1 plain scene."""
    from tests.data.corpus.data import make_v2_corpus

    return make_v2_corpus(tmp_path_factory.mktemp("v2"), n_scenes=3, frames=4, n_plain=1)


_V2_CASES = {
    "default": {},
    "random-start-rolling-ramps": dict(frame_start="random", shutter="rolling", pwm={
        "sync": "group", "rise_time_s": {"dist": "uniform", "low": 0.0, "high": 2e-4},
        "fall_time_s": {"dist": "uniform", "low": 0.0, "high": 2e-4}}),
    "test-split-frozen": dict(split="test", frame_start="random"),
}


@pytest.mark.parametrize("case", sorted(_V2_CASES))
def test_the_batched_program_composes_every_light_kind_of_scene_version_2(v2_corpus, case):
    """Gated lights (indicator, strobe, countdown, destination display), message-sign scan rows and shared drivers
    on the device program (device="cpu") against the per-sample path: draws identical, captures within the
    float32 summation bound (the weights are the same float64 function, GateTable.exposure, on the batch's
    tensors). The scenes' gates switch inside the frames drawn, so some gated slots are dark and others lit."""
    from lfmbench.datasets.batch_compose import pwm_weights
    from lfmbench.datasets.pwm import has_light_timing

    kw = dict(split="all", frames=3, crop=(12, 16), samples_per_scene=2, outputs=OUTS, seed=7)
    kw.update(_V2_CASES[case])
    if kw["split"] == "test":
        kw["samples_per_scene"] = 3
    db = _program_against_the_per_sample_path(v2_corpus, kw, case)
    prog = db.resident.program
    timed = sum(has_light_timing(db.ds.scene(sid).meta) for sid in prog.sids)
    assert timed and prog.gates.shape[0] == 4 * timed and prog.any_scan      # 4 gated lights per timed scene
    pieces = prog.pieces(range(len(db.ds)))
    gt = pwm_weights(pieces)["gt"][pieces["gate_slot"]]                          # (G, R, K) s
    lit = gt.sum((1, 2)) > 0
    assert lit.any() and (~lit).any(), case


def test_rolling_gates_evaluated_on_their_rows_only_equal_the_full_evaluation(v2_corpus):
    """Under a rolling shutter the gated slots' weights are computed only on the rows of their boxes
    (``gate_span``, ``info["gate_height"]``): at every row an entry of a gated slot reads they equal the
    evaluation on every row of the crop (the same element-wise float64 function of the same row starts, so bit
    for bit), and they are 0 on the other rows; the per-sample path's pieces carry the same spans."""
    from lfmbench.datasets.batch_compose import pwm_weights

    kw = dict(split="all", frames=3, crop=None, samples_per_scene=2, outputs=OUTS, seed=7, shutter="rolling")
    db = DeviceBatches(LFMCaptureDataset(v2_corpus, **kw), batch_size=6, device="cpu", seed=3)
    pieces = db.resident.program.pieces(range(len(db.ds)))
    h = pieces["info"]["crop_hw"][0]
    hb = pieces["info"]["gate_height"]
    assert 0 < hb < h                                               # the restricted evaluation is taken
    full = pwm_weights({**{k: v for k, v in pieces.items() if k != "gate_span"}})
    part = pwm_weights(pieces)
    is_gate, slot, row, inside = _gated_entry_rows(pieces)
    on = is_gate[slot]
    assert on.sum() > 0 and inside[slot[on], row[on]].all()       # every gated entry lies in its span
    gs = pieces["gate_slot"]
    for k in ("lpd", "spd", "gt"):
        assert torch.equal(part[k][slot[on], row[on]], full[k][slot[on], row[on]]), k
        assert torch.equal(part[k][~is_gate], full[k][~is_gate]), k
        assert not part[k][gs][~inside[gs]].any(), k
        assert full[k][gs][~inside[gs]].abs().sum() > 0, k          # the full evaluation did fill those rows
    # the per-sample path's pieces (collated on the host): spans that hold their entries too
    ds = db.ds
    host = collate_pieces([capture_pieces(ds, *ds.draws(i)[:5]) for i in range(len(ds))])
    assert 0 < host["info"]["gate_height"] < h
    is_gate, slot, row, inside = _gated_entry_rows(host)
    assert is_gate[slot].sum() > 0 and inside[slot[is_gate[slot]], row[is_gate[slot]]].all()


def _gated_entry_rows(pieces):
    """(is_gate (S,) bool, entry slot (E,), entry row (E,), inside (S, h) bool: the rows of each gated span)."""
    h, w = pieces["info"]["crop_hw"]
    is_gate = torch.zeros(pieces["slot_K"].shape[0], dtype=torch.bool)
    is_gate[pieces["gate_slot"]] = True
    slot, row = pieces["entry_slot"].long(), (pieces["entry_pix"].long() % (h * w)) // w
    inside = torch.zeros(pieces["slot_K"].shape[0], h, dtype=torch.bool)
    for g, (r0, r1) in zip(pieces["gate_slot"].tolist(), pieces["gate_span"].tolist()):
        inside[g, r0:r1] = True
    return is_gate, slot, row, inside


def test_counter_draws_differ_between_epochs_seeds_and_samples(long_corpus):
    """The counter streams are not degenerate: other epochs, seeds and samples get other draws; the test split's
    frozen draws do not change with the epoch or the seed."""
    kw = dict(frames=3, crop=(12, 16), samples_per_scene=3, noise_streams="counter", frame_start="random")
    a = LFMCaptureDataset(long_corpus, split="all", seed=1, **kw)
    b = LFMCaptureDataset(long_corpus, split="all", seed=2, **kw)
    d0 = [a.draws(i) for i in range(len(a))]
    a.set_epoch(1)
    d1 = [a.draws(i) for i in range(len(a))]
    db = [b.draws(i) for i in range(len(b))]
    for other in (d1, db):
        assert sum(x[1] != y[1] for x, y in zip(d0, other)) == len(d0)          # PWM of every sample
        assert len({x[4] for x in d0 + other}) == 2 * len(d0)                    # noise seeds
    assert len({x[1][min(x[1])]["phase_s"] for x in d0}) == len(d0)               # samples of one scene differ
    assert len({x[3][:2] for x in d0}) > 1 and len({x[5] for x in d0}) > 1       # crops and window starts vary
    t = LFMCaptureDataset(long_corpus, split="test", seed=1, **kw)
    before = [t.draws(i) for i in range(len(t))]
    t.set_epoch(3)
    assert before == [t.draws(i) for i in range(len(t))]


def test_device_batches_do_not_depend_on_the_batch_size(corpus):
    a = DeviceBatches(_ds(corpus), batch_size=2, device="cpu", seed=1)
    b = DeviceBatches(_ds(corpus), batch_size=9, device="cpu", seed=1)
    big = next(iter(b))
    small = [x for x in a]
    for k in ("lpd_hcg", "spd_e", "gt", "light_index"):
        assert torch.equal(torch.cat([x[k] for x in small]), big[k]), k
    a.set_epoch(1)
    assert not torch.equal(next(iter(a))["gt"], small[0]["gt"])  # another epoch: other draws


def test_split_that_does_not_fit_is_refused_before_copying(corpus):
    ds = _ds(corpus)
    need = ResidentScenes.estimate(ds)
    with pytest.raises(ResidentMemoryError, match=r"split 'all' .* scenes need .* GiB on cpu .* the budget is"):
        ResidentScenes(ds, "cpu", budget_bytes=need - 1)
    with pytest.raises(ValueError, match="batch_size"):
        DeviceBatches(ds, 0, "cpu")
    with pytest.raises(ValueError, match="noise_streams"):
        _ds(corpus, noise_streams="philox")
    pieces = [capture_pieces(ds, *ds.draws(0)[:5])]
    with pytest.raises(ValueError, match="noise_streams"):
        simulate_batch(collate_pieces(pieces), ds.preset, noise_streams="philox")


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")
def test_cuda_device_batches_match_the_cpu(corpus):
    cpu = next(iter(DeviceBatches(_ds(corpus), batch_size=9, device="cpu", seed=1)))
    gpu = next(iter(DeviceBatches(_ds(corpus), batch_size=9, device="cuda", seed=1)))
    for k in ("lpd_hcg", "spd_e", "gt", "light_index", "depth"):
        assert gpu[k].device.type == "cuda"
        g, c = gpu[k].cpu(), cpu[k]
        if g.is_floating_point() and k != "lpd_hcg":
            # float32 sums in another order (index_add_ with atomics) and another rounding of divisions on the GPU
            close = torch.isclose(g, c, rtol=1e-5, atol=1e-5 * float(c.abs().max()), equal_nan=True)
            assert close.double().mean() >= 0.999, (k, float(close.double().mean()))
        else:  # DN and indices: a composed mean that moved in its last bit can move a noise draw or a rounding
            assert (g != c).double().mean() <= 2e-3, k


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")
def test_cuda_entry_kernel_cuts_the_torch_forms_entries(corpus):
    """On CUDA the crops' lamp entries come from one Triton kernel: the torch form's entries bit for bit (the same
    integer arithmetic; the rates are copied and multiplied by the same 1.0 or 0.0); the crops of the static,
    light-index and depth layers from a row-copy kernel: the torch form's gathers, bit for bit."""
    import warnings

    import lfmbench.datasets.device as D

    if D._ENTRY_KERNELS.module() is None:
        pytest.skip("Triton is not importable")
    db = DeviceBatches(_ds(corpus), batch_size=9, device="cuda", seed=1)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)      # a kernel that fails to compile warns: an error here
        a = db.pieces(range(9))
    assert D._ENTRY_KERNELS.enabled
    D._ENTRY_KERNELS.enabled = False
    try:
        b = db.pieces(range(9))
    finally:
        D._ENTRY_KERNELS.enabled = True
    assert a["entry_pix"].shape[0] > 0 and "static" in a
    for k in ("entry_pix", "entry_slot", "entry_values", "static", "light_index", "depth"):
        if k in b:
            assert a[k].shape == b[k].shape and a[k].dtype == b[k].dtype, k
            assert torch.equal(a[k], b[k]), k


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")
def test_cuda_prefetched_batches_are_the_same_batches(corpus):
    """prefetch=True makes each batch on a side stream one batch ahead: the same batches in the same order, whole
    epochs of them, and a second epoch again. The draws (meta, crops, slots) are equal; the composed means are sums
    of float32 atomic adds on a GPU, whose order varies from run to run (the torch form's index_add_ and the
    Triton pass alike: a first H100 run of this test found `gt` equal, a second one 1 ulp apart), so floats are
    compared within float32 rounding and a count may move where a mean moved (as the CPU comparison allows)."""
    from lfmbench.datasets.batched import tensor_leaves

    plain = DeviceBatches(_ds(corpus), batch_size=5, device="cuda", seed=2)
    ahead = DeviceBatches(_ds(corpus), batch_size=5, device="cuda", seed=2, prefetch=True)
    for epoch in (0, 1):
        plain.set_epoch(epoch)
        ahead.set_epoch(epoch)
        a, b = list(plain), list(ahead)
        assert len(a) == len(b) == len(plain) > 1
        for x, y in zip(a, b):
            xs, ys = dict(tensor_leaves(x)), dict(tensor_leaves(y))
            assert xs.keys() == ys.keys()
            for k in xs:
                g, c = ys[k], xs[k]
                assert g.shape == c.shape and g.dtype == c.dtype, (epoch, k)
                if k[0] == "meta" or not g.is_floating_point() and k[0] in ("light_index",):
                    assert torch.equal(g, c), (epoch, k)
                elif g.is_floating_point() and k[0] not in ("lpd_hcg", "lpd_lcg", "spd"):
                    close = torch.isclose(g, c, rtol=1e-5, atol=1e-5 * float(c.abs().max()), equal_nan=True)
                    assert close.double().mean() >= 0.999, (epoch, k)
                else:
                    assert (g != c).double().mean() <= 2e-3, (epoch, k)


def test_prefetch_is_ignored_off_cuda(corpus):
    """On the CPU prefetch=True changes nothing (no side stream there)."""
    plain = list(DeviceBatches(_ds(corpus), batch_size=5, device="cpu", seed=2))
    ahead = list(DeviceBatches(_ds(corpus), batch_size=5, device="cpu", seed=2, prefetch=True))
    assert len(plain) == len(ahead) > 1
    for x, y in zip(plain, ahead):
        assert torch.equal(x["lpd_hcg"], y["lpd_hcg"]) and torch.equal(x["gt"], y["gt"])


def test_train_from_the_device_path(tmp_path, corpus):
    """train(..., data="device") runs the one training loop on DeviceBatches: it learns (the loss moves), writes
    its checkpoint and resumes like the loader path; an unknown data source is refused."""
    from lfmbench.train import train

    kw = dict(epochs=2, crop=16, batch_size=4, samples_per_scene=2, split="all", progress=False, log=None)
    model, hist = train("unet", corpus, tmp_path / "u.pt", device="cpu", data="device", **kw)
    assert len(hist["epoch_loss"]) == 2 and all(torch.isfinite(torch.tensor(hist["epoch_loss"])))
    assert (tmp_path / "u.pt").is_file()
    _, again = train("unet", corpus, tmp_path / "u.pt", device="cpu", data="device", **kw)  # resumes: nothing to do
    assert again["epoch_loss"] == hist["epoch_loss"]
    with pytest.raises(ValueError, match="data must be one of"):
        train("unet", corpus, tmp_path / "v.pt", device="cpu", data="gpu", **kw)


def test_a_sample_without_lights_or_groups_in_its_crop_stays_on_the_device(tmp_path):
    """A crop that shows no lamp (no pixel entries) still gives its empty entry tensors on the resident device."""
    from tests.data.corpus.data import make_corpus

    root = make_corpus(tmp_path / "c", n_scenes=1, groups={"headlights": {"flicker": False},
                                                           "otherlights": {"flicker": True}})
    ds = LFMCaptureDataset(root, split="all", frames=2, crop=(2, 2), outputs=OUTS)
    res = ResidentScenes(ds, "meta")  # a device other than the CPU that needs no GPU: shapes only
    sid, pl, pg, _crop, ns, start = ds.draws(0)
    for crop in ((6, 20, 2, 2), (0, 0, 8, 8)):                  # no entries; entries of a lamp
        p = capture_pieces(ds, sid, pl, pg, crop, ns, 0, start, resident=res)
        for k in ("static", "entry_values", "entry_slot", "entry_pix", "light_index", "depth"):
            assert p[k].device.type == "meta", (crop, k)
    assert p["entry_values"].shape[2] > 0


def test_gather_rows_equals_index_select():
    """gather_rows (a Triton kernel on CUDA) returns index_select's rows, for any row width and index dtype."""
    from lfmbench.datasets.row_gather import gather_rows

    devs = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])
    for dev in devs:
        for shape in ((50, 2, 8), (50, 3), (50, 1), (50, 2, 3)):
            t = torch.rand(shape, device=dev)
            for dt in (torch.int64, torch.int32):
                i = torch.randint(0, 50, (37,), device=dev, dtype=dt)
                assert torch.equal(gather_rows(t, i), t.index_select(0, i)), (dev, shape, dt)
        assert gather_rows(torch.rand(4, 2, device=dev), torch.zeros(0, dtype=torch.long, device=dev)).shape == (0, 2)


def test_float16_residency_halves_the_rates_within_its_error_bound(long_corpus):
    """Layers stored as float16 (each scene scaled by a power of two): the bytes of the rates halve; the composed
    ground truth and captures' means stay within 2^-11 relative of the float32 path (float16 keeps 11 significant
    bits; a sum of non-negative terms keeps the largest relative error of its terms), the masks and depth exact."""
    kw = dict(split="all", frames=3, crop=(12, 16), samples_per_scene=3, outputs=OUTS, noise=False)
    a = DeviceBatches(LFMCaptureDataset(long_corpus, **kw), batch_size=9, device="cpu", seed=2)
    h = DeviceBatches(LFMCaptureDataset(long_corpus, **kw), batch_size=9, device="cpu", seed=2, dtype=torch.float16)
    assert h.resident.program.static.dtype == torch.float16
    assert h.resident.bytes < 0.75 * a.resident.bytes
    assert h.resident.bytes == ResidentScenes.estimate(h.ds, dtype=torch.float16)
    for x, y in zip(a, h):
        assert torch.equal(x["light_index"], y["light_index"]) and torch.equal(x["depth"], y["depth"])
        rel = (y["gt"] - x["gt"]).abs() / x["gt"].abs().clamp_min(1e-30)
        assert float(rel.max()) <= 2.0 ** -11 + 1e-6, float(rel.max())
        for k in ("lpd_hcg", "lpd_lcg", "spd"):       # DN: a mean moved by 2^-11 crosses at most that many steps
            d = (y[k].double() - x[k].double()).abs()
            assert bool((d <= 1 + 2.0 ** -11 * x[k].double()).all()), (k, float(d.max()))
        assert not torch.equal(x["gt"], y["gt"])          # it is float16 storage, not a copy of the float32 one
    with pytest.raises(ValueError, match="dtype must be one of"):
        ResidentScenes(a.ds, "cpu", dtype=torch.bfloat16)


def test_a_split_streamed_in_chunks_serves_every_sample_once_with_the_same_numbers(long_corpus):
    """chunk_scenes: a budget that holds one scene refuses the whole split (naming chunk_scenes) but streams it one
    scene at a time; every sample of the epoch comes exactly once, each equal to the whole-split batch's sample."""
    kw = dict(split="all", frames=3, crop=(12, 16), samples_per_scene=3, outputs=OUTS)
    ds = LFMCaptureDataset(long_corpus, **kw)
    one = max(ResidentScenes.estimate_scene(ds, s, kall=4) for s in ds.scene_ids)
    one += DeviceBatches.batch_bytes(ds, 4)  # the budget holds the batch too
    with pytest.raises(ResidentMemoryError, match=r"chunk_scenes=1"):
        DeviceBatches(ds, 4, "cpu", budget_bytes=one + 1)
    whole = DeviceBatches(LFMCaptureDataset(long_corpus, **kw), batch_size=len(ds), device="cpu", seed=4)
    whole.set_epoch(1)
    ref = next(iter(whole))
    at = {i: j for j, i in enumerate(ref["meta"]["index"].tolist())}
    st = DeviceBatches(LFMCaptureDataset(long_corpus, **kw), batch_size=2, device="cpu", seed=4, chunk_scenes=1,
                       budget_bytes=one + 1)
    st.set_epoch(1)
    seen = []
    batches = list(st)
    assert len(batches) == len(st) == 3 * 2                      # 3 chunks of 3 samples: batches of 2 and 1
    for batch in batches:
        for j, i in enumerate(batch["meta"]["index"].tolist()):
            seen.append(i)
            for k in ("gt", "lpd_hcg", "light_index"):
                assert torch.equal(batch[k][j], ref[k][at[i]]), (i, k)
    assert sorted(seen) == list(range(len(ds)))
    with pytest.raises(ValueError, match="chunk_scenes"):
        DeviceBatches(ds, 2, "cpu", chunk_scenes=0)
    fresh = DeviceBatches(LFMCaptureDataset(long_corpus, **kw), batch_size=2, device="cpu", seed=4, chunk_scenes=1)
    held = fresh.resident                    # epoch 0 starts from the chunk loaded (and budget-checked) at init
    next(iter(fresh))
    assert fresh.resident is held


def test_train_on_float16_layers_streamed_in_chunks(tmp_path, corpus):
    """train(data="device") with float16 layers and the split streamed 2 scenes at a time: it runs, the loss is
    finite; an unknown storage type is refused naming the argument."""
    from lfmbench.train import train

    kw = dict(epochs=1, crop=16, batch_size=4, samples_per_scene=2, split="all", progress=False, log=None,
              device="cpu", data="device")
    _model, hist = train("unet", corpus, tmp_path / "u.pt", resident_dtype="float16", chunk_scenes=2, **kw)
    assert hist["steps"] == 2 and all(torch.isfinite(torch.tensor(hist["step_loss"])))   # chunks of 4 and 2 samples
    with pytest.raises(ValueError, match="resident_dtype"):
        train("unet", corpus, tmp_path / "v.pt", resident_dtype="bf16", **kw)


def test_training_a_split_pixel_network_on_another_architecture_is_refused_at_once(tmp_path, corpus):
    """The small learned baseline reads split-pixel captures: train.sensor of another architecture is refused
    before any work, naming the sensor, its baselines and what trains for it (the U-Net takes any plan)."""
    from lfmbench.train import train

    with pytest.raises(ValueError, match=r"train.sensor: learned .* 'lofic' is a lofic sensor; its baselines .*"
                                         r"\(trainable: unet\)"):
        train("learned", corpus, tmp_path / "u.pt", sensor="lofic", epochs=1, crop=16, batch_size=2, split="all",
              progress=False, log=None)
    assert not (tmp_path / "u.pt").exists()


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")
def test_cuda_graphed_training_step_trains_as_the_eager_step(tmp_path, corpus):
    """train() on CUDA with the step replayed as a CUDA graph (after 3 eager warm-up steps; an epoch's smaller last
    batch eagerly) against cuda_graph="off": the same step losses and weights within float32 noise of cuDNN's
    kernels (same data, same initial weights, same optimiser arithmetic)."""
    import warnings

    from lfmbench.train import train
    from lfmbench.train_step import GraphedStep

    kw = dict(epochs=2, crop=16, batch_size=4, samples_per_scene=5, split="all", progress=False, log=None,
              device="cuda", data="device")
    replays = []
    real_call = GraphedStep.__call__

    def spy(self, batch, lr):
        out = real_call(self, batch, lr)
        replays.append(self.replays)
        return out

    with warnings.catch_warnings():
        warnings.filterwarnings("error", message="CUDA graph")      # a failed capture must fail this test
        GraphedStep.__call__ = spy
        try:
            m_g, h_g = train("unet", corpus, tmp_path / "g.pt", cuda_graph="auto", **kw)
        finally:
            GraphedStep.__call__ = real_call
    m_e, h_e = train("unet", corpus, tmp_path / "e.pt", cuda_graph="off", **kw)
    assert replays and replays[-1] >= 3                                          # the graph ran
    assert torch.allclose(torch.tensor(h_g["step_loss"]), torch.tensor(h_e["step_loss"]), rtol=1e-3, atol=1e-5)
    for (k, a), b in zip(m_g.state_dict().items(), m_e.state_dict().values()):
        assert torch.allclose(a.float(), b.float(), rtol=1e-3, atol=1e-4), k


def test_cuda_graph_mode_is_checked(tmp_path, corpus):
    from lfmbench.train import train

    with pytest.raises(ValueError, match="cuda_graph must be one of"):
        train("unet", corpus, tmp_path / "u.pt", device="cpu", cuda_graph="on", epochs=1, crop=16, batch_size=4,
              samples_per_scene=1, split="all", progress=False, log=None)


def test_a_chunk_budget_holds_the_batches_and_the_last_chunk_is_freed_before_the_next(long_corpus, monkeypatch):
    """An explicit budget covers one chunk's layers plus the batch (``DeviceBatches.batch_bytes``: the bytes of a
    batch the path really yields); a chunk is loaded only after the previous one is released."""
    import weakref

    from lfmbench.datasets import device as dev
    from lfmbench.datasets.batched import tensor_leaves

    kw = dict(split="all", frames=3, crop=(12, 16), samples_per_scene=3, outputs=OUTS)
    ds = LFMCaptureDataset(long_corpus, **kw)
    bb = DeviceBatches.batch_bytes(ds, 3)
    whole = DeviceBatches(LFMCaptureDataset(long_corpus, **kw), batch_size=3, device="cpu")
    got = sum(t.numel() * t.element_size() for p, t in tensor_leaves(next(iter(whole))) if p[0] != "meta")
    assert got <= bb <= 2 * got  # the yielded batch's tensors (meta aside), as the estimate says
    one = max(ResidentScenes.estimate_scene(ds, s, kall=4) for s in ds.scene_ids)
    with pytest.raises(ResidentMemoryError, match=r"the batches alone take"):
        DeviceBatches(ds, 3, "cpu", budget_bytes=bb, chunk_scenes=1)
    with pytest.raises(ResidentMemoryError, match=r"1 scenes need"):
        DeviceBatches(ds, 3, "cpu", budget_bytes=one + bb - 1, chunk_scenes=1)  # layers fit, layers + batch not
    alive: list = []

    class Watched(ResidentScenes):
        def __init__(self, *a, **k):
            assert all(r() is None for r in alive), "the previous chunk is still held"
            super().__init__(*a, **k)
            alive.append(weakref.ref(self))

    monkeypatch.setattr(dev, "ResidentScenes", Watched)
    st = DeviceBatches(LFMCaptureDataset(long_corpus, **kw), batch_size=3, device="cpu", seed=2, chunk_scenes=1,
                       budget_bytes=one + bb)
    st.set_epoch(1)
    seen = [i for b in st for i in b["meta"]["index"].tolist()]
    assert sorted(seen) == list(range(len(ds))) and len(alive) >= 3  # every chunk loaded, each after the last freed
