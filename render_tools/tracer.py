"""Batched light-set path tracing: every window, light group, light crop and time bin of a frame in few launches.

Why (docs/benchmarks/render.md, "Where the time goes"): with one ``mi.render`` per window, group and light, a
new scene cost 44 renders per frame, each traced anew in Python and, whenever anything scene-dependent was a
literal in the kernel (shutter length, film size, group layout), compiled anew by LLVM (3-5 s each). Here a
frame is a list of :class:`Tile` s (a crop of the image, a time window split into K bins, a sample count and a
*light set*: the emitters whose light this tile records) and one Dr.Jit kernel renders any list of tiles:
everything that differs between tiles, frames and scenes is data (gathered from opaque arrays), so the kernel
is traced once per launch and compiled once per (variant, kind of sky, number of static groups): a new scene of a
class already compiled is a cache hit (:func:`pad_registry`, docs/guide/rendering.md).

Light sets replace per-group and per-light Mitsuba scenes. The scene is loaded once per frame with every
emitter on; a lane of set ``k`` counts only emission of the emitters in ``k`` (a light group, or one light's
lamp face plus its beam) and samples next-event estimation only from them: at each path vertex one emitter of the
set, drawn in proportion to an estimate of the light it brings to that point (intensity, beam cone or face
cosine, receiver cosine, inverse square distance; on a glossy coat such as a wet road's water film, times the
coat's specular lobe towards the lamp: :meth:`Tracer._lamp_weights`), so that of 40 streetlights the few near the
point (or the one it reflects) get the samples (uniform or flux-proportional choice spent most of them on far lamps). By linearity of light transport in the emission this is exactly the image
of the scene in which only set ``k`` emits (the previous per-group scenes; checked against Mitsuba's own
``path`` integrator in tests/render_tools/test_render_tracer.py).

The path tracer follows Mitsuba 3's ``path`` integrator (and the primal loop of its Python ``prb``): unidirectional
path tracing with next-event estimation for smooth BSDFs, multiple importance sampling with the balance
heuristic (:func:`_mis_weight`, as Mitsuba's), emitters visible to camera rays, ``max_depth`` vertices, Russian
roulette (Mitsuba's rule) for the paths that go on from the second hit (:data:`RR_DEPTH`).

Camera: the ego camera of :mod:`render_tools.camera` (CTRV pose at the ray's time; OpenCV intrinsics of
:func:`camera.intrinsics`; pixel (i, j) covers [j, j + 1) x [i, i + 1)), generated here so that crop, time
window and object velocity are per-tile data. Spectral sampling: band-stratified passes as in
:mod:`render_tools.camera` (pass p carries one wavelength uniformly inside each of bands p + j * P, j = 0..3,
P = ceil(C / 4)); each sample adds its radiance at lambda_j straight to band p + j * P (the band average of the
radiance is the expectation of L at a uniform wavelength in the band), so no film or sensitivity function is
involved. Sample dimensions of the camera (pixel x, y, time, wavelength) are stratified over a pixel's ``spp``
samples (each dimension its own random rotation of the strata, so each is uniform and independent of the others
in expectation); tiles with ``sobol`` (scene version 2) take pixel x, y, time and the first vertex's light sample
from randomly shifted Sobol' points instead (:func:`sobol_points`), and tiles with ``block`` trace one lane per
2 x 2 px block (wet-road reflections).

Over 500 lines for now: the tile list, the light-set registry and the one Dr.Jit kernel that renders them are kept
together until the tracer's rework settles; the kernel and the tile planning are to be split apart.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import drjit as dr
import mitsuba as mi
import numpy as np

from . import camera as cam_mod
from . import mitsuba_scene as ms
from .kernel_rules import lane_divisor

#: Wavelengths per Mitsuba spectral sample (MI_SPECTRUM_SAMPLES).
N_LAMBDA = 4
#: Most samples (lanes x samples per pixel) in one kernel launch (bigger tile lists are split into several launches
#: of the same kernel; a tile with more is split by samples).
MAX_LANES = 1 << 28
#: Path vertex from which Russian roulette may end a path (Mitsuba's ``rr_depth``, whose default 5 never acts at
#: ``max_depth`` 5): vertices 3-5 cost 40 % of a night frame's time and carry little of its light.
RR_DEPTH = 2
#: Side (px) of the pixel blocks a :class:`Tile` with ``block`` > 1 traces as one (the only such size).
BLOCK = 2
#: Index value meaning "no set" in the per-emitter lookup tables.
NO_SET = 0xFFFFFFFF
#: Beam cut-off cosine entries of a :class:`LightSets` row meaning "a lamp without a beam" and "the environment".
NO_BEAM, ENV_ROW = -2.0, -3.0
#: Bound of the 1 / d^2 of a lamp's selection weight near the lamp: d^2 is taken as at least this, m^2.
LIGHT_R2_M2 = 0.05
#: Floor of a selection weight's angular factors (behind a face, outside a beam, grazing receiver): every emitter
#: keeps a positive probability, so next-event estimation stays unbiased whatever the weights get wrong.
WEIGHT_FLOOR = 1e-3
#: Lower bound of emitted spectral radiance (W sr^-1 m^-2 nm^-1) in the tracer. Mitsuba's ``sunsky`` (Hosek-Wilkie
#: fit) returns negative values near the horizon at short wavelengths when the sun is low: at sun elevation 1.1 deg
#: (dusk) 1.5e-5 of random directions, down to -3.8e-5 against a sky peak of 1.1e-2 (measured, Mitsuba 3.9.1); a
#: frame then held radiance below -1e-6 x its peak and the corpus writer refused it (12 of 33 dusk scenes of the
#: lfmbench-v1-mini protocol). The tracer uses max(L_e, 0): the image of the sky with its negative lobes cut off.
EMISSION_FLOOR = 0.0
#: Floor of the receiver cosine in the selection weight.
RECEIVER_FLOOR = 0.1
#: Floor of the cosine product in a glossy coat's factor of the selection weight (:meth:`Tracer._lamp_weights`).
GLOSS_COS_FLOOR = 1e-2


#: Smallest registry size class per kind of Mitsuba object (:func:`registry_class`): above what a generated scene
#: has (120 scenes of the default generator: 108-207 shapes, 5-92 emitters, 42-58 BSDFs), so that generated scenes
#: with the same kind of sky and number of static groups run the same kernel; a bigger scene pads to the next power
#: of two.
REGISTRY_CLASS_MIN = {"shape": 256, "emitter": 128, "bsdf": 64}


def registry_class(n: int, kind: str = "shape") -> int:
    """The size class of ``n`` registered Mitsuba objects of ``kind`` (``shape``, ``emitter``, ``bsdf``): the
    smallest power of two >= max(n, :data:`REGISTRY_CLASS_MIN` [kind])."""
    return max(REGISTRY_CLASS_MIN[kind], 1 << max(0, int(n) - 1).bit_length())


def registry_id(mi, dr, ptr_type, obj) -> int:
    """Dr.Jit registry id of Mitsuba object ``obj`` (``ptr_type``: ``mi.EmitterPtr``, ``mi.ShapePtr``,
    ``mi.BSDFPtr``): what a kernel's pointer arrays hold (0 = none)."""
    return int(dr.reinterpret_array(mi.UInt32, ptr_type(obj))[0])


#: Index of refraction of a ``roughplastic`` coat whose scene material gives no ``ior``: Mitsuba 3's default
#: ``int_ior`` of its ``roughplastic`` plugin ("polypropylene", 1.49; Mitsuba 3 plugin reference, "Rough plastic
#: material", https://mitsuba.readthedocs.io/en/stable/src/generated/plugins_bsdfs.html), which
#: :mod:`render_tools.mitsuba_scene` leaves in place for such a material.
ROUGHPLASTIC_IOR = 1.49


def glossy_choice_table(mi, dr, bsdfs: dict, materials: dict) -> dict:
    """BSDF registry id -> (GGX alpha, c) of the scene's glossy coats for :class:`Tracer` ``gloss``: every material
    of ``materials`` (name -> scene material) that is a ``roughplastic`` (a wet road's water film and its puddles,
    glass, car paint, lamp lenses, signs; a missing ``ior`` is Mitsuba's, :data:`ROUGHPLASTIC_IOR`), ``bsdfs``
    (name -> its loaded Mitsuba BSDF, shared by its shapes). ``c = F0 pi eta^2 / (4 rho)`` with F0 = ((eta - 1) /
    (eta + 1))^2 at normal incidence and rho the mean of the material's ``rgb`` (its texture's base colour).

    Every coat, not only the water film's (protocol version 6 of lfmbench-v2): a shop window mirroring an oncoming
    car's headlights got the plain choice before, so its reflection was a few spp-1 samples ~5x their mean, which
    the denoiser removed (0.29 of an undenoised reference's light kept at 160x90, 0.79 at 640x360; 1.05 with the
    lobe's choice; docs/benchmarks/rendering-measurements.md, "A lit window at the left edge")."""
    out = {}
    for name, m in materials.items():
        if m.get("type") != "roughplastic" or name not in bsdfs:
            continue
        eta = float(m.get("ior", ROUGHPLASTIC_IOR))
        f0 = ((eta - 1.0) / (eta + 1.0)) ** 2
        rho = max(float(np.mean(m["rgb"])), 1e-3)
        out[registry_id(mi, dr, mi.BSDFPtr, bsdfs[name])] = (float(m["alpha"]), f0 * math.pi * eta * eta / (4.0 * rho))
    return out


def pad_registry(mi, dr, loaded, bsdf) -> list:
    """Pad Dr.Jit's registry of shapes, emitters and BSDFs to their size classes with inert objects.

    Why: a kernel's virtual-call tables have one entry per registered object of a kind (Dr.Jit's registry id
    bound), and their sizes enter the kernel as literal offsets (the LLVM IR of two night scenes with 37 and 58
    lights differed in these offsets and in the environment's id, :meth:`Tracer._radiance`), so every new scene
    compiled a new kernel (1.3-3.5 s at 160x90 on 2 cores). Padding each kind to :func:`registry_class` of its id
    bound makes scenes of one class share a kernel.

    The dummies are never part of ``loaded``: nothing can hit or sample them, so the image is unchanged (bit for
    bit; tests/render_tools/test_render_tracer.py). Each kind gets at least one dummy of a fixed type (a ``spot`` emitter of the
    beams' spectrum type, a one-triangle mesh with ``bsdf``, a ``diffuse`` BSDF), so the set of object types, which
    also enters the kernel, does not depend on whether a scene happens to fill its class or has beams.

    The first dummy mesh has a BSDF of its own (a ``diffuse``, made before the BSDF ids are counted), the others
    ``bsdf``: the shapes' BSDFs then never all agree. Where they did (a scene whose every shape has one BSDF, as
    small test scenes), Dr.Jit wrote that BSDF's id into the kernel as a literal (its calls fold a value that all
    instances share), a kernel of its own for such scenes.
    ``loaded``: the frame's ``mi.Scene``; ``bsdf``: a BSDF of the scene for the dummy meshes. Returns the dummies:
    keep them alive while the frame's kernels are traced; freeing them frees their ids.
    """
    def rid(ptr_type, obj):
        return registry_id(mi, dr, ptr_type, obj)

    shapes = list(loaded.shapes())
    own = mi.load_dict({"type": "diffuse"})  # the first dummy mesh's BSDF, counted with the scene's
    bsdfs = {rid(mi.BSDFPtr, b): b for b in [sh.bsdf() for sh in shapes] + [bsdf, own] if b is not None}
    meshes = []

    def mesh():
        meshes.append(_dummy_mesh(mi, bsdf if meshes else own))
        return meshes[-1]

    kinds = (  # emitters first: none of the later dummies registers an emitter, and meshes need no new BSDF
        ("emitter", mi.EmitterPtr, [rid(mi.EmitterPtr, e) for e in loaded.emitters()],
         lambda: mi.load_dict(ms.pad_emitter_dict())),
        ("shape", mi.ShapePtr, [rid(mi.ShapePtr, sh) for sh in shapes], mesh),
        ("bsdf", mi.BSDFPtr, list(bsdfs), lambda: mi.load_dict({"type": "diffuse"})),
    )
    dummies = [own]
    for kind, ptr_type, ids, make in kinds:
        target = registry_class(max(ids, default=0) + 1, kind)
        while True:  # Dr.Jit hands out the lowest free id: the holes fill first, then the ids up to the target
            obj = make()
            dummies.append(obj)
            if rid(ptr_type, obj) >= target:
                break
    return dummies


def _dummy_mesh(mi, bsdf):
    """A one-triangle mesh with ``bsdf``, in no scene (a :func:`pad_registry` dummy)."""
    props = mi.Properties()
    props["bsdf"] = bsdf
    return mi.Mesh("lfm_pad", 3, 1, props=props)


@dataclass
class Tile:
    """One rectangle of the image to render.

    crop: (y0, x0, y1, x1) px of the full image, end exclusive. bins: K time bins of ``bin_len`` s from
    ``t_start`` s (absolute time). spp: samples per pixel per band pass and bin. light_set: index of the light
    set (:class:`LightSets`). velocity: (3,) m/s world velocity of an object held at its ``t_ref`` (s) position,
    rendered as relative camera motion (0 for none). key: 32-bit integer naming the tile; a lane's random
    numbers depend only on (seed, key, its index in the tile), so a tile renders the same whatever else is in
    the list (a group left out changes nothing in the others). gap_at, gap_len: a time interval [gap_at,
    gap_at + gap_len) (s, absolute) cut out of a one-bin tile: its samples cover [t_start, t_start + bin_len +
    gap_len) minus the gap (a long exposure without the short one inside it). The tile's output is (K, C, h, w)
    float32 radiance, W sr^-1 m^-2 nm^-1, each bin the time average over its interval. slots: the number of
    images the tile records, 1, or for a tile of a *union* set (:class:`LightSets`) its number of member groups:
    the output is then (slots, K, C, h, w), one image per group in the union's order. pass_spp: samples per
    pixel and bin of each band pass (P integers >= 1, powers of two to keep the strata; P = ceil(C / 4)) instead
    of ``spp`` in every pass: band c is the mean of pass c mod P's samples, so each band stays unbiased whatever
    the split (:func:`render_tools.render.lamp_pass_spp` gives a lamp's passes samples by its spectrum). sobol:
    pixel x, y and time of a pixel's samples from a randomly shifted Sobol' sequence (:func:`sobol_points`)
    instead of per-dimension strata paired at random (scene version 2; ``RenderOptions.pixel_samples``). block:
    1, or :data:`BLOCK` to trace one lane per BLOCK x BLOCK pixels (its samples spread over the block, its mean
    written to each of them: the block's average light, a box blur of the tile's image at 1 / BLOCK^2 the
    samples; ``RenderOptions.reflection_block_px``).
    """

    crop: tuple
    bins: int
    t_start: float
    bin_len: float
    spp: int
    light_set: int
    velocity: tuple = (0.0, 0.0, 0.0)
    t_ref: float = 0.0
    key: int = 0
    gap_at: float = math.inf
    gap_len: float = 0.0
    slots: int = 1
    pass_spp: tuple | None = None
    sobol: bool = False
    block: int = 1

    @property
    def shape(self) -> tuple[int, int]:
        y0, x0, y1, x1 = self.crop
        return y1 - y0, x1 - x0


class LightSets:
    """The light sets of a loaded frame scene and what next-event estimation needs to pick a light in them.

    Sets: one per light group present (``group:<name>``: every emitter of the group; ``skymap`` is the
    environment emitter) and one per light (``light:<id>``: its lamp face and its beam, if any). Built from the
    shape/emitter ids of :func:`render_tools.mitsuba_scene.mitsuba_dict` (scene loaded with ``emit="all"``).

    One row per lamp (the members of set k are rows ``start[k]`` .. ``start[k] + count[k] - 1``): its face
    emitter and beam emitter (or none), position (m, world), axis (unit), the cosine of the beam's cut-off
    (:data:`NO_BEAM` without one, :data:`ENV_ROW` for the environment) and intensity (cd: luminance x face
    area); :meth:`Tracer._lamp_weights` turns them into selection weights at a shading point.

    ``union`` (group names, at least two of ``groups``): one more set, ``union:static``, whose members are the
    rows of those groups, each row tagged with its group's *slot* (its index in ``union``). A lane of a union set
    follows one camera path and records the light of every member group separately, one image per slot
    (:class:`Tile` ``slots``): emission hits go to the slot of the emitter hit, and next-event estimation draws
    one emitter of the whole union (:meth:`Tracer._choose_light`). By linearity each slot's image is the image of
    the scene in which only that group emits, as with one set per group, at about a third of the camera paths and
    shadow rays for three groups (docs/guide/rendering.md, "Static groups in one pass").
    """

    def __init__(self, mi, dr, loaded, scene: dict, groups, union=()):
        self.names: list[str] = []
        members: list[list] = []  # per set: [(face emitter, beam emitter or None, geometry row)]
        union = list(union)
        if union and (len(union) < 2 or len(set(union)) != len(union) or not set(union) <= set(groups)):
            raise ValueError(f"union: needs two or more distinct groups of {list(groups)}, got {union}")
        self.union: list[str] = union
        #: Images per lane: the number of groups of the union set (1 without one).
        self.slots: int = max(1, len(union))
        by_light: dict[int, tuple] = {}
        sky = []
        shapes = {sh.id(): sh for sh in loaded.shapes()}
        emitters = {em.id(): em for em in loaded.emitters()}
        for lt in scene["lights"]:
            sh = shapes.get(ms.light_shape_id(lt["id"]))
            if sh is None or sh.emitter() is None:
                continue
            n = np.asarray(lt["normal"], dtype=np.float64)
            n = n / np.linalg.norm(n)
            bb = sh.bbox()
            c = 0.5 * (np.array(bb.min, dtype=np.float64) + np.array(bb.max, dtype=np.float64))
            beam = emitters.get(ms.beam_id(lt["id"]))
            cos_cut = math.cos(math.radians(float(lt["spread_deg"]))) if beam is not None else NO_BEAM
            inten = max(float(lt["luminance_cd_m2"]) * ms.plane_area(lt), 1e-12)
            by_light[lt["id"]] = (sh.emitter(), beam, (*c, *n, cos_cut, inten))
        for em in loaded.emitters():
            if em.is_environment():
                sky.append((em, None, (0.0, 0.0, 0.0, 0.0, 0.0, 1.0, ENV_ROW, 1.0)))
        self.index: dict[str, int] = {}

        def add(name, rows):
            if not rows:
                return
            self.index[name] = len(self.names)
            self.names.append(name)
            members.append(rows)

        for g in groups:
            if g == "skymap":
                add("group:skymap", sky)
            else:
                add(f"group:{g}", [by_light[lt["id"]] for lt in scene["lights"]
                                   if lt["group"] == g and lt["id"] in by_light])
        for lid, row in by_light.items():
            add(f"light:{lid}", [row])
        slot_of_row: list[int] = []  # slot of each row of the union set, in member order
        if union:
            urows = []
            for j, g in enumerate(union):
                mem = members[self.index[f"group:{g}"]] if f"group:{g}" in self.index else []
                urows += mem
                slot_of_row += [j] * len(mem)
            add("union:static", urows)
        # flat rows; per emitter registry id: (its group set, row, is beam), (its light set, row, is beam) and
        # (its union set, row, is beam)
        rows, faces, beams, start, count, slot = [], [], [], [], [], []
        group_of, light_of, union_of = {}, {}, {}

        def eid(e):
            return registry_id(mi, dr, mi.EmitterPtr, e)

        for k, mem in enumerate(members):
            start.append(len(rows))
            count.append(len(mem))
            kind = self.names[k].split(":")[0]
            of = {"group": group_of, "light": light_of, "union": union_of}[kind]
            for m, (face, beam, geo) in enumerate(mem):
                of[eid(face)] = (k, len(rows), 0)
                if beam is not None:
                    of[eid(beam)] = (k, len(rows), 1)
                faces.append(face)
                beams.append(beam)
                rows.append(geo)
                slot.append(slot_of_row[m] if kind == "union" else 0)
        n_id = max(list(group_of) + list(light_of), default=0) + 1
        # per emitter: group set, its row, is beam; light set, row, is beam; union set, row, is beam
        tab = np.full((9, n_id), NO_SET, np.uint32)
        for j, of in ((0, group_of), (3, light_of), (6, union_of)):
            for e, (k, r, isb) in of.items():
                tab[j, e], tab[j + 1, e], tab[j + 2, e] = k, r, isb
        # a dummy last entry: no table has a single entry (Dr.Jit loads size-1 arrays as scalars with an alignment
        # that depends on the allocation, which changes the kernel's hash and forces a recompile)
        self.faces = mi.EmitterPtr(faces + faces[-1:]) if faces else None
        self.beams = mi.EmitterPtr(beams + beams[-1:]) if faces else None
        self.start = mi.UInt32(np.asarray(start + [0], np.uint32))
        self.count = mi.UInt32(np.asarray(count + [0], np.uint32))
        self.tab = [mi.UInt32(t) for t in np.concatenate([tab, np.full((9, 1), NO_SET, np.uint32)], 1)]
        self.slot = mi.UInt32(np.asarray(slot + slot[-1:] if slot else [0, 0], np.uint32))
        geo = np.asarray(rows + rows[-1:] if rows else [[0.0] * 8] * 2, dtype=np.float32).T
        self.geo = [mi.Float(np.ascontiguousarray(c)) for c in geo]
        self.n_id = dr.opaque(mi.UInt32, n_id)

    def __contains__(self, name: str) -> bool:
        return name in self.index

    def __getitem__(self, name: str) -> int:
        return self.index[name]


def _permute(i, key, dim: int, mask):
    """A keyed bijection of [0, mask] (mask = 2^k - 1; UInt32 arrays) built from steps that are bijective modulo
    2^k: xor with a key, multiplication by an odd number, xor with a right shift of itself (a hash-based
    permutation in the spirit of Kensler, "Correlated multi-jittered sampling", Pixar TM 13-01, 2013)."""
    k = key * ((2 * dim + 1) * 0x9E3779B1 & 0xFFFFFFFF)
    i = (i ^ k) & mask
    i = (i * ((k >> 1) | 1)) & mask
    i = i ^ ((i & mask) >> 1)
    i = (i * 0x2C1B3C6D) & mask
    i = i ^ (i >> 2)
    i = (i ^ (k >> 7)) & mask
    i = (i * 0x297A2D39) & mask
    return i ^ (i >> 1)


def _sobol_directions(s: int, a: int, m: tuple, bits: int = 32) -> tuple[int, ...]:
    """Direction numbers v_1..v_bits (32-bit integers) of one Sobol' dimension from its primitive polynomial of
    degree ``s`` with coefficients ``a`` and initial numbers ``m`` (S. Joe, F. Y. Kuo, "Constructing Sobol
    sequences with better two-dimensional projections", SIAM J. Sci. Comput. 30(5), 2008; their table
    new-joe-kuo-6.21201: dimension 2: s 1, a 0, m 1; dimension 3: s 2, a 1, m 1 3)."""
    v = [0] * bits
    for i, mi_ in enumerate(m):
        v[i] = mi_ << (31 - i)
    for i in range(len(m), bits):
        x = v[i - s] ^ (v[i - s] >> s)
        for k in range(1, s):
            if (a >> (s - 1 - k)) & 1:
                x ^= v[i - k]
        v[i] = x
    return tuple(v)


#: Direction numbers of the Sobol' dimensions used for pixel x, pixel y, time and the first vertex's light sample
#: (2-D): the van der Corput sequence (dimension 1) and dimensions 2-5 of Joe and Kuo (new-joe-kuo-6.21201: d 4:
#: s 3, a 1, m 1 3 1; d 5: s 3, a 2, m 1 1 1); their first 2^m points are a (0, m, 2)-net in (x, y).
SOBOL_DIRECTIONS = (tuple(1 << (31 - i) for i in range(32)), _sobol_directions(1, 0, (1,)),
                    _sobol_directions(2, 1, (1, 3)), _sobol_directions(3, 1, (1, 3, 1)),
                    _sobol_directions(3, 2, (1, 1, 1)))
#: Sobol' dimensions: pixel x, pixel y, time, then the 2-D sample of the first vertex's next-event estimation.
SOBOL_X, SOBOL_Y, SOBOL_T, SOBOL_LIGHT = 0, 1, 2, 3
#: Index bits of a Sobol' point the kernel reads (samples of a pixel beyond 2^SOBOL_BITS repeat its points; each
#: point is still uniform through its random shift, so the estimate stays unbiased).
SOBOL_BITS = 16


def sobol_points(index: np.ndarray, shifts: np.ndarray) -> np.ndarray:
    """Reference (numpy) of the kernel's Sobol' points: ``index`` (n,) non-negative integers, ``shifts`` (D,) or
    (D, n) 32-bit random digital shifts, D <= 5 dimensions -> (D, n) float64 in [0, 1): dimension d of point i is (the i-th point of
    Sobol' dimension d, as 32 bits, XOR shift_d) / 2^32, truncated to 24 bits as the kernel's float32. A random
    digital shift makes each point uniform on [0, 1)^3 (unbiased estimates) and keeps the net's strata: of 2^m
    points, each of the 2^m cells [i / 2^a, (i + 1) / 2^a) x [j / 2^b, (j + 1) / 2^b), a + b = m, of (x, y) holds
    exactly one (I. M. Sobol', USSR Comput. Math. Math. Phys. 7(4), 1967; A. B. Owen, "Monte Carlo and quasi-Monte
    Carlo for statistics", 2009, on randomized nets)."""
    index = np.asarray(index, np.uint64)
    shifts = np.asarray(shifts, np.uint64)
    D = shifts.shape[0]
    out = np.zeros((D, index.size), np.uint64)
    for d, V in enumerate(SOBOL_DIRECTIONS[:D]):
        for j in range(SOBOL_BITS):
            out[d] ^= np.where((index >> np.uint64(j)) & np.uint64(1), np.uint64(V[j]), np.uint64(0))
    out ^= shifts.reshape(D, -1)
    return ((out & np.uint64(0xFFFFFFFF)) >> np.uint64(8)).astype(np.float64) / 2.0 ** 24


def _sobol_dim(i, shift, d: int):
    """Dimension ``d`` of Sobol' point ``i`` (UInt32 per lane) XOR ``shift`` (UInt32), as Float in [0, 1) (24 bits)."""
    acc = mi.UInt32(shift)
    for j in range(SOBOL_BITS):
        bit = (i >> j) & 1
        acc ^= mi.UInt32(SOBOL_DIRECTIONS[d][j]) & (mi.UInt32(0) - bit)
    return mi.Float(acc >> 8) * (1.0 / (1 << 24))


def _sobol_shifts(pkey):
    """The 5 random 32-bit digital shifts (UInt32) of a pixel's Sobol' points, from its key ``pkey`` (UInt32)."""
    sh0, sh1 = mi.sample_tea_32(pkey, mi.UInt32(0x1B873593))
    sh2, sh3 = mi.sample_tea_32(pkey, mi.UInt32(0xCC9E2D51))
    return sh0, sh1, sh2, sh3, mi.sample_tea_32(pkey, mi.UInt32(0xE6546B64))[0]


def _sobol_sample(qmc, shifts, s, ux, uy, ut):
    """Sample ``s`` of a lane's pass: (x, y, t in [0, 1), the first vertex's light sample Point2f) from the shifted
    Sobol' point p nmax + s where the lane's ``sobol`` flag is set, else ``ux``, ``uy``, ``ut`` and the Sobol'
    light sample unused. ``qmc`` = (sobol Bool, pkey, p, nmax) as :meth:`Tracer._pixel` takes it."""
    sobol, _, p, nmax = qmc
    i = p * nmax + s  # pass p's block of the pixel's sequence
    return (dr.select(sobol, _sobol_dim(i, shifts[0], SOBOL_X), ux),
            dr.select(sobol, _sobol_dim(i, shifts[1], SOBOL_Y), uy),
            dr.select(sobol, _sobol_dim(i, shifts[2], SOBOL_T), ut),
            mi.Point2f(_sobol_dim(i, shifts[3], SOBOL_LIGHT), _sobol_dim(i, shifts[4], SOBOL_LIGHT + 1)))


def _lane_grid(h: int, w: int, block: int) -> tuple[int, int]:
    """Rows and columns of lanes of an h x w px tile traced in ``block`` x ``block`` px blocks (host integers)."""
    return -(-h // block), -(-w // block)


def _mis_weight(pdf_a, pdf_b):
    """Balance heuristic pdf_a / (pdf_a + pdf_b) (0 where both are 0), as Mitsuba's ``mis_weight``."""
    w = pdf_a / (pdf_a + pdf_b)
    return dr.detach(dr.select(dr.isfinite(w), w, 0))


class Tracer:
    """Renders lists of :class:`Tile` s of one loaded frame scene (see module docstring).

    Args:
        mi, dr: the Mitsuba and Dr.Jit modules (variant already set).
        loaded: the ``mi.Scene`` of the frame (all emitters on).
        sets: its :class:`LightSets`.
        ego: :class:`camera.EgoMotion`; fov_x_deg: horizontal field of view, deg; size: (width, height) px.
        bands_nm: (C,) band centres, nm; band_width_nm: band width, nm. max_depth: path vertices (Mitsuba's).
        sky_scale: factor on the environment emitter's radiance, for a scene loaded with a unit-scale ``sunsky``
            (``mitsuba_dict(unit_sky=True)``; :func:`render_tools.mitsuba_scene.sky_scale`): kernel data here,
            where Mitsuba's ``sky_scale`` is a literal (a new kernel per scene).
        gloss: BSDF registry id -> (GGX alpha, specular-to-diffuse factor ``c``) of the glossy coats whose lobe the
            light choice follows (:func:`glossy_choice_table`, :meth:`_lamp_weights`); None or empty: none (every
            weight as without it, bit for bit).
    """

    def __init__(self, mi, dr, loaded, sets: LightSets, ego, fov_x_deg: float, size, bands_nm, band_width_nm: float,
                 max_depth: int = ms.MAX_DEPTH, sky_scale: float = 1.0, gloss: dict | None = None):
        self.mi, self.dr, self.scene, self.sets = mi, dr, loaded, sets
        self.W, self.H = int(size[0]), int(size[1])
        self.C = len(bands_nm)
        self.P = cam_mod.n_passes(self.C)
        self.max_depth = int(max_depth)
        # images per lane: the union set's groups (1 without a union). Not padded to 3 so that scenes with one, two
        # or three static groups share a kernel: that cost 3-5 % per frame of a sky-only day scene, more than the
        # one-time compile of each of these (at most 3) kernel classes, which the disk cache keeps
        self.S = int(sets.slots)
        K = cam_mod.intrinsics(self.W, self.H, fov_x_deg)
        o = lambda v: dr.opaque(mi.Float, float(v))  # noqa: E731 - every scene number is kernel data
        self.f, self.cx, self.cy = o(K[0, 0]), o(K[0, 2]), o(K[1, 2])
        self.p0 = [o(v) for v in ego.p0]
        self.yaw0, self.yaw_rate, self.speed = o(ego.yaw0_rad), o(ego.yaw_rate_rad_s), o(ego.speed_mps)
        th = -ego.pitch_rad
        ry = np.array([[math.cos(th), 0, math.sin(th)], [0, 1, 0], [-math.sin(th), 0, math.cos(th)]])
        self.m0 = [[o(x) for x in row] for row in (ry @ cam_mod.R_VEHICLE_FROM_MI)]
        lo = [c - band_width_nm / 2 for c in bands_nm] + [500.0] * (self.P * N_LAMBDA - self.C)
        self.band_lo = mi.Float(np.asarray(lo, np.float32))
        self.band_w = o(band_width_nm)
        self.n_bands = dr.opaque(mi.UInt32, self.C)
        self.n_pass = dr.opaque(mi.UInt32, self.P)
        env = loaded.environment()
        self.env = mi.EmitterPtr([env, env])  # two entries: a size-1 array would be loaded as a scalar
        self.env_id = dr.opaque(mi.UInt32, registry_id(mi, dr, mi.EmitterPtr, env) if env is not None else NO_SET)
        self.sky_scale = o(sky_scale)
        gl = dict(gloss or {})
        n_g = max([int(k) for k in gl] + [1]) + 1  # at least 2 entries: a size-1 array would load as a scalar
        ga, gc = np.zeros(n_g, np.float32), np.zeros(n_g, np.float32)
        for k, (al, c) in gl.items():
            ga[int(k)], gc[int(k)] = al, c
        self.gloss_a, self.gloss_c = mi.Float(ga), mi.Float(gc)
        self.n_gloss = dr.opaque(mi.UInt32, n_g)

    # ------------------------------------------------------------------ camera
    def _pose(self, t):
        """Camera centre (Point3f, m) and (cos, sin) of the yaw at absolute time ``t`` (s): CTRV written with
        sinc so that it is exact and stable for any yaw rate, including 0."""
        mi, dr = self.mi, self.dr
        half = 0.5 * self.yaw_rate * t
        sinc = dr.select(dr.abs(half) < 1e-4, 1.0 - half * half / 6.0, dr.sin(half) / dr.select(half == 0, 1.0, half))
        dist = self.speed * t * sinc
        mid = self.yaw0 + half
        p = mi.Point3f(self.p0[0] + dist * dr.cos(mid), self.p0[1] + dist * dr.sin(mid), self.p0[2])
        psi = self.yaw0 + 2.0 * half
        return p, dr.cos(psi), dr.sin(psi)

    def _rot(self, v, c, s):
        m = self.m0
        x = m[0][0] * v[0] + m[0][1] * v[1] + m[0][2] * v[2]
        y = m[1][0] * v[0] + m[1][1] * v[1] + m[1][2] * v[2]
        z = m[2][0] * v[0] + m[2][1] * v[1] + m[2][2] * v[2]
        return self.mi.Vector3f(c * x - s * y, s * x + c * y, z)

    def camera_ray(self, px, py, t, vel=None, t_ref=None):
        """World ray (``mi.Ray3f``) through image position (px, py) (px, continuous, x right, y down) at time
        ``t`` (s); ``vel`` (Vector3f, m/s) and ``t_ref`` (s): the camera also moves by ``-vel (t - t_ref)``."""
        mi, dr = self.mi, self.dr
        d_local = [-(px - self.cx) / self.f, -(py - self.cy) / self.f, mi.Float(1.0)]
        p, c, s = self._pose(t)
        if vel is not None:
            p = p - vel * (t - t_ref)
        d = dr.normalize(self._rot(d_local, c, s))
        # near clip as Mitsuba's perspective camera: the ray starts on the plane z_cam = NEAR_CLIP_M
        inv_z = dr.norm(mi.Vector3f(d_local[0], d_local[1], d_local[2]))
        o = p + d * (cam_mod.NEAR_CLIP_M * inv_z)
        ray = mi.Ray3f(o, d)
        ray.time = t
        return ray

    # ------------------------------------------------------------------ tiles
    def render(self, tiles: list, seed: int) -> list[np.ndarray]:
        """Render ``tiles``; returns one (K, C, h, w) float32 array per tile (radiance, W sr^-1 m^-2 nm^-1).

        Tiles are packed into launches of at most :data:`MAX_LANES` lanes (a tile larger than that is split by
        samples); ``seed`` (int >= 0) seeds the launch's random numbers (each launch gets seed + its index).
        """
        mi, dr = self.mi, self.dr
        C, P = self.C, self.P
        outs, size = [], 0
        parts = []  # (tile index, spp of this part, weight, out offset, part index)
        for i, t in enumerate(tiles):
            h, w = t.shape
            if h <= 0 or w <= 0 or t.bins < 1 or t.spp < 1:
                raise ValueError(f"tiles[{i}]: empty crop {t.crop}, bins {t.bins} or spp {t.spp}")
            if t.gap_len < 0 or (t.gap_len > 0 and t.bins != 1):
                raise ValueError(f"tiles[{i}]: a time gap needs gap_len >= 0 s and one bin, got {t.gap_len} s, "
                                 f"{t.bins} bins")
            if t.block not in (1, BLOCK):
                raise ValueError(f"tiles[{i}]: block must be 1 or {BLOCK}, got {t.block}")
            if not 1 <= t.slots <= self.S:
                raise ValueError(f"tiles[{i}]: slots {t.slots} not in [1, {self.S}] (the light sets' union has "
                                 f"{self.S} group(s))")
            outs.append((size, (t.slots, t.bins, C, h, w) if t.slots > 1 else (t.bins, C, h, w)))
            lh, lw = _lane_grid(h, w, t.block)  # one lane per block
            if t.pass_spp is None:
                n_split = max(1, -(-lh * lw * t.bins * P * t.spp // MAX_LANES))
                base, extra = divmod(t.spp, n_split)
                for j in range(n_split):
                    sp = base + (j < extra)
                    if sp:
                        parts.append((i, sp, 1.0 / t.spp, size, j))
            else:  # per pass counts: every part has every pass's lanes, a pass out of samples weighs 0
                ps = [int(n) for n in t.pass_spp]
                if len(ps) != P or min(ps) < 1:
                    raise ValueError(f"tiles[{i}]: pass_spp needs {P} counts >= 1, got {t.pass_spp}")
                n_split = max(1, -(-lh * lw * t.bins * sum(ps) // MAX_LANES))
                shares = [divmod(n, n_split) for n in ps]  # (base, extra) of each pass, as for spp above
                for j in range(min(n_split, max(ps))):
                    sp = tuple(b + (j < e) for b, e in shares)
                    parts.append((i, sp, tuple(1.0 / n if c else 0.0 for n, c in zip(ps, sp)), size, j))
            size += t.slots * t.bins * C * h * w
        buf = dr.zeros(mi.Float, max(size, 1))
        batch, lanes = [], 0
        launch = 0
        for part in parts:
            t = tiles[part[0]]
            h, w = _lane_grid(*t.shape, t.block)
            n = h * w * t.bins * (P * part[1] if isinstance(part[1], int) else sum(max(c, 1) for c in part[1]))
            # samples (the launch's work), lanes = samples / spp
            if batch and lanes + n > MAX_LANES:
                self._launch(buf, tiles, batch, seed + launch)
                launch += 1
                batch, lanes = [], 0
            batch.append(part)
            lanes += n
        if batch:
            self._launch(buf, tiles, batch, seed + launch)
        host = np.asarray(buf, dtype=np.float32)
        return [host[o:o + int(np.prod(shp))].reshape(shp) for o, shp in outs]

    def _launch(self, buf, tiles, parts, seed: int) -> None:
        mi, dr = self.mi, self.dr
        rows, per_pass = [], []
        off = 0
        for i, sp, wgt, out, j in parts:
            t = tiles[i]
            y0, x0, y1, x1 = t.crop
            key = (int(t.key) * 0x9E3779B1 + j * 0x85EBCA77) & 0xFFFFFFFF
            sp_p = (sp,) * self.P if isinstance(sp, int) else sp  # samples of each band pass
            wgt_p = (wgt,) * self.P if isinstance(wgt, float) else wgt
            per_pass += [(max(n, 1), w_) for n, w_ in zip(sp_p, wgt_p)]  # a pass without samples: 1 of weight 0
            rows.append((off, y0, x0, y1 - y0, x1 - x0, t.bins, 0, t.light_set, out, t.t_start, t.bin_len, 0.0,
                         *[float(v) for v in t.velocity], t.t_ref, key, min(t.gap_at, 3e38), t.gap_len, t.slots,
                         float(bool(t.sobol)), max(sp_p), t.block))
            lh, lw = _lane_grid(y1 - y0, x1 - x0, t.block)
            off += lh * lw * t.bins * self.P
        # a dummy last row: no table has a single entry (Dr.Jit loads size-1 arrays as scalars with an alignment
        # that depends on the allocation, which changes the kernel's hash and forces a recompile)
        a = np.array(rows + [rows[-1]], dtype=np.float64)
        pp = np.array(per_pass + per_pass[-self.P:], dtype=np.float64)  # (rows + 1) x P, row-major
        U = lambda c: mi.UInt32(a[:, c].astype(np.uint32))  # noqa: E731
        F = lambda c: mi.Float(a[:, c].astype(np.float32))  # noqa: E731
        tab = {"off": mi.UInt32(np.append(a[:-1, 0], off).astype(np.uint32)), "y0": U(1), "x0": U(2), "h": U(3),
               "w": U(4), "K": U(5), "set": U(7), "out": U(8), "t0": F(9), "dt": F(10),
               "vx": F(12), "vy": F(13), "vz": F(14), "tref": F(15), "key": U(16), "gap": F(17), "gap_len": F(18), "slots": U(19), "sobol": U(20), "nmax": U(21), "block": U(22),
               "spp": mi.UInt32(pp[:, 0].astype(np.uint32)), "wgt": mi.Float(pp[:, 1].astype(np.float32))}
        n_tiles = dr.opaque(mi.UInt32, len(rows))
        # Sobol' points and pixel blocks are compiled in only when a tile of the launch asks for them: the kernels of
        # scenes without them (every lfmbench-v1 scene) stay the code, and the cost, they were
        self._trace(buf, tab, n_tiles, off, seed, any(tiles[i].sobol for i, *_ in parts),
                    any(tiles[i].block > 1 for i, *_ in parts))
        dr.eval(buf)

    def _trace(self, buf, tab, n_tiles, n_lanes: int, seed: int, use_sobol: bool = False,
               use_block: bool = False) -> None:
        """One lane per (tile, band pass, bin, pixel or block of pixels): it loops over its samples and writes its
        4 bands once (to each pixel of its block), so no two lanes of a launch add to the same value
        (deterministic sums, no atomics). ``use_sobol`` / ``use_block``: compile in the per-tile Sobol' points /
        pixel blocks (some tile of the launch has them)."""
        mi, dr = self.mi, self.dr
        lane = dr.arange(mi.UInt32, n_lanes)
        # tile of each lane: binary search over the lane offsets (fixed 20 steps: up to 2^20 tiles)
        lo, hi = mi.UInt32(0), mi.UInt32(n_tiles)  # invariant off[lo] <= lane < off[hi]
        for _ in range(20):
            mid = (lo + hi) >> 1
            go = dr.gather(mi.UInt32, tab["off"], mid) <= lane
            lo = dr.select(go, mid, lo)
            hi = dr.select(go, hi, mid)
        ti = lo
        g = lambda k, T=mi.UInt32: dr.gather(T, tab[k], ti)  # noqa: E731
        # divisors clamped to >= 1: the masked tail lanes of the last packet gather 0 (kernel_rules)
        w, h, K = (lane_divisor(g(k)) for k in ("w", "h", "K"))
        local = lane - g("off")
        if use_block:
            b = lane_divisor(g("block"))  # 1, or BLOCK: the lane grid has one lane per b x b pixels
            lw, lh = lane_divisor((w + b - 1) // b), lane_divisor((h + b - 1) // b)
            bx = local % lw
            r = local // lw
            by = r % lh
            r = r // lh
            x, y = bx * b, by * b  # the block's first pixel in the tile
            fw, fh = dr.minimum(b, w - x), dr.minimum(b, h - y)  # its size inside the tile, px
            foot = (mi.Float(fw), mi.Float(fh))
        else:
            lw, lh = w, h
            x = local % w
            r = local // w
            y = r % h
            r = r // h
            foot = None
        k = r % K
        p = r // K
        pass_row = ti * self.n_pass + p  # the tile's entry for band pass p in the per-pass tables
        spp = lane_divisor(dr.gather(mi.UInt32, tab["spp"], pass_row))
        seed_o = dr.opaque(mi.UInt32, seed)
        tkey = mi.sample_tea_32(g("key"), seed_o)[0]
        v0, v1 = mi.sample_tea_32(tkey, local)
        sampler = mi.PCG32()
        sampler.seed(mi.UInt64(v0) | (mi.UInt64(v1) << 32), mi.UInt64(tkey) | (mi.UInt64(local) << 32))
        rot = mi.sample_tea_32(local, tkey + 0x9E3779B9)[0] % spp  # random rotation of the wavelength strata
        bands = [p + j * self.n_pass for j in range(N_LAMBDA)]
        lo_nm = [dr.gather(mi.Float, self.band_lo, b) for b in bands]
        vel = mi.Vector3f(g("vx", mi.Float), g("vy", mi.Float), g("vz", mi.Float))
        L = self._pixel(sampler, spp, rot, mi.sample_tea_32(local, tkey + 0x3C6EF372)[0], mi.Float(g("x0") + x),
                        mi.Float(g("y0") + y), g("t0", mi.Float) + mi.Float(k) * g("dt", mi.Float),
                        g("dt", mi.Float), vel, g("tref", mi.Float), lo_nm, g("set"), g("gap", mi.Float),
                        g("gap_len", mi.Float),
                        (g("sobol") != 0, mi.sample_tea_32(local % (K * lh * lw), tkey + 0x61C88647)[0], p,
                         g("nmax")) if use_sobol else None, foot)
        wgt = dr.gather(mi.Float, tab["wgt"], pass_row)
        out0 = g("out")
        n_slots = g("slots")
        stride = K * self.n_bands * h * w  # one image of the tile (a slot)
        span = BLOCK if use_block else 1
        for sl in range(self.S):
            for j in range(N_LAMBDA):
                for dy in range(span):  # every pixel of the block (one of them when b is 1) gets the lane's mean
                    for dx in range(span):
                        idx = out0 + sl * stride + ((k * self.n_bands + bands[j]) * h + y + dy) * w + x + dx
                        # mode Local, not Auto: Auto expands a buffer of <= 1 M values per thread with the buffer's
                        # size as a kernel literal (a new kernel per size); frames of 160x90 and more got Local
                        on = (bands[j] < self.n_bands) & (sl < n_slots)
                        if dx or dy:
                            on &= (dx < fw) & (dy < fh)
                        dr.scatter_reduce(dr.ReduceOp.Add, buf, L[sl][j] * wgt, idx, on,
                                          mode=dr.ReduceMode.Local)

    @dr.syntax
    def _pixel(self, sampler, spp, rot, key, x0, y0, t0, dt, vel, t_ref, lo_nm, lset, gap_at, gap_len, qmc=None,
               foot=None):
        """Sum over ``spp`` samples (UInt32 per lane) of the radiance through the pixel [x0, x0 + 1) x [y0, y0 + 1)
        (px; ``foot`` = (fw, fh) Float: the block [x0, x0 + fw) x [y0, y0 + fh) instead) at uniform times in
        [t0, t0 + dt) (s), times at or after ``gap_at`` moved on by ``gap_len`` (s);
        wavelength j of a sample is uniform in [lo_nm[j],
        lo_nm[j] + band width) (nm), stratified over the samples (stratum (s + rot) mod spp). Pixel x, y and
        time are stratified too, each through its own permutation of the strata keyed by ``key`` (UInt32 per
        lane; :func:`_permute`), so that the strata of different dimensions are paired at random: one rotation
        per dimension would pair them along diagonals, which for a lamp moving across a pixel aliased and
        raised the variance several times. ``qmc`` = (sobol, pkey, p, nmax): where ``sobol`` (Bool per lane) is
        set, x, y and time, and the first vertex's light sample, come from the Sobol' points of
        :func:`sobol_points` instead: point p ``nmax`` + s for sample s of band
        pass p (``nmax``: the most samples of any pass of the tile, a power of two like each pass's count),
        shifted by random 32-bit XORs drawn from ``pkey`` (UInt32, the same for every pass of a pixel and bin). A
        block of 2^m points starting at a multiple of 2^m is a net, so each pass's samples are one (a band sees its
        pass's samples only), and with equal counts all passes' together are the first P nmax points, one net too
        (the static frames' one sample per pass: the pixel's 8 samples stratified): a moving lamp edge crossing a
        pixel is an indicator in (x, y, t), which strata paired at random stratify only along each axis, and the
        sky or lamp light at the first hit is then sampled in stratified directions (docs/benchmarks/render.md,
        "Pixel samples"). The strata's random numbers are drawn either way, so a lane's other dimensions see the
        same random stream. Non-finite samples are dropped (counted as 0). Returns one sum per slot (list of
        :attr:`S` ``mi.Spectrum``)."""
        acc = [mi.Spectrum(0.0) for _ in range(self.S)]
        shifts = None if qmc is None else _sobol_shifts(qmc[1])  # (no `if` statements: @dr.syntax would trace them)
        spp = lane_divisor(spp)  # a divisor below (kernel_rules); the caller's is clamped already
        s = mi.UInt32(0)
        inv = dr.rcp(mi.Float(spp))
        pow2 = (spp & (spp - 1)) == 0
        mask = spp - 1
        while s < spp:
            # pixel x, y and time: each stratified over the samples by its own keyed permutation of the strata
            # (a power of two spp; else independent uniform draws)
            ux = dr.select(pow2, (mi.Float(_permute(s, key, 1, mask)) + sampler.next_float32()) * inv,
                           sampler.next_float32())
            uy = dr.select(pow2, (mi.Float(_permute(s, key, 2, mask)) + sampler.next_float32()) * inv,
                           sampler.next_float32())
            ut = dr.select(pow2, (mi.Float(_permute(s, key, 3, mask)) + sampler.next_float32()) * inv,
                           sampler.next_float32())
            ux, uy, ut, u_light = (ux, uy, ut, None) if qmc is None else _sobol_sample(qmc, shifts, s, ux, uy, ut)
            px, py = (x0 + ux, y0 + uy) if foot is None else (x0 + foot[0] * ux, y0 + foot[1] * uy)
            t = t0 + dt * ut
            t = dr.select(t >= gap_at, t + gap_len, t)
            ray = self.camera_ray(px, py, t, vel, t_ref)
            u = (mi.Float((s + rot) % spp) + sampler.next_float32()) * inv
            ray.wavelengths = mi.Spectrum(lo_nm[0] + u * self.band_w, lo_nm[1] + u * self.band_w,
                                          lo_nm[2] + u * self.band_w, lo_nm[3] + u * self.band_w)
            L = self._radiance(sampler, ray, lset) if qmc is None else \
                self._radiance(sampler, ray, lset, qmc[0], u_light)
            acc = [acc[j] + mi.Spectrum(dr.select(dr.isfinite(L[j]), L[j], 0.0)) for j in range(self.S)]
            s += 1
        return acc

    def _lamp_weights(self, row, p, n, wi=None, gloss=None):
        """Selection weights of lamp ``row`` (UInt32, a row of :class:`LightSets`) at a shading point ``p``
        (Point3f, m) with normal ``n`` (Vector3f): (face, beam), each an estimate of the light that emitter
        brings there: intensity (cd) x emission factor (the face's Lambertian cosine; the beam: 1 inside its cone,
        else 0) x receiver |cosine| (floored at :data:`RECEIVER_FLOOR`) / max(d^2, :data:`LIGHT_R2_M2`) (m^2),
        the point-light estimate behind power- and distance-aware light samplers (M. Pharr, W. Jakob,
        G. Humphreys, Physically Based Rendering, 4th ed., 2023, section 12.6). The environment: (1, 0).
        Angular factors are floored at :data:`WEIGHT_FLOOR`, so no emitter's probability is ever 0: the estimate
        stays unbiased whatever the weights get wrong, they only steer the samples.

        ``wi`` (Vector3f, unit, towards the viewer) and ``gloss`` = (alpha, c) (Float; alpha 0: none) at a point on
        a glossy coat (a wet road's water film, :func:`glossy_choice_table`): the weight is multiplied by the coat's
        specular-to-diffuse ratio towards the lamp's centre, ``1 + c D(h) / max(cos_i cos_o, GLOSS_COS_FLOOR)``
        (GGX D of the half vector h, B. Walter, S. R. Marschner, H. Li, K. E. Torrance, "Microfacet models for
        refraction through rough surfaces", EGSR 2007, eq. 33; ``c = F0 pi eta^2 / (4 rho)``: the specular
        lobe F D G / (4 cos_i cos_o) over a diffuse base rho / (pi eta^2), shadowing and Fresnel's rise at grazing
        left out), so the lamp whose reflection the point shows gets the samples: without it, the streetlight in
        a wet road's mirror direction (30-60 m away) was drawn with a few % probability against the lamps overhead
        and its streak was sparse bright samples at spp 1 (docs/benchmarks/gallery.md)."""
        mi, dr = self.mi, self.dr
        G = [dr.gather(mi.Float, c, row) for c in self.sets.geo]
        d = mi.Vector3f(p[0] - G[0], p[1] - G[1], p[2] - G[2])  # from the lamp to the point
        d2 = dr.squared_norm(d)
        inv = dr.rsqrt(dr.maximum(d2, 1e-12))
        cos_e = (d[0] * G[3] + d[1] * G[4] + d[2] * G[5]) * inv
        rec = dr.maximum(dr.abs(dr.dot(n, d)) * inv, RECEIVER_FLOOR)
        base = G[7] * rec / dr.maximum(d2, LIGHT_R2_M2)
        if gloss is not None:
            alpha, c = gloss
            h = wi - d * inv  # wi + the unit direction to the lamp
            ch = dr.abs(dr.dot(h, n)) * dr.rsqrt(dr.maximum(dr.squared_norm(h), 1e-12))
            a2 = alpha * alpha
            q = ch * ch * (a2 - 1.0) + 1.0
            D = a2 / (math.pi * q * q)
            cc = dr.maximum(dr.abs(dr.dot(n, wi)) * dr.abs(dr.dot(n, d)) * inv, GLOSS_COS_FLOOR)
            base = base * dr.select(alpha > 0, 1.0 + c * D / cc, 1.0)
        env = G[6] == ENV_ROW
        w_face = dr.select(env, 1.0, base * dr.maximum(cos_e, WEIGHT_FLOOR))
        w_beam = dr.select(G[6] > NO_BEAM, base * dr.select(cos_e >= G[6] - 1e-2, 1.0, WEIGHT_FLOOR), 0.0)
        return w_face, w_beam

    @dr.syntax
    def _choose_light(self, sampler, start, cnt, p, n, active, wi=None, gloss=None):
        """Draw one emitter of a lane's set (lamp rows ``start`` .. ``start + cnt - 1``, each a face and maybe a
        beam) with probability in proportion to its weight (:meth:`_lamp_weights`) at (``p``, ``n``): a lamp by
        weighted reservoir sampling over the rows (one pass, one uniform per row: row r replaces the choice with
        probability w_r / (w_0 + ... + w_r); M. T. Chao, "A general purpose unequal probability sampling plan",
        Biometrika 69, 1982), then its face or beam in proportion to their weights. A union set's rows are the
        lamps of all its groups, so the draw goes where most light comes from, whichever group it belongs to.
        Returns (emitter, its probability, sum of all weights, the slot of its row: 0 outside a union)."""
        i = mi.UInt32(0)
        wsum = mi.Float(0.0)
        row = mi.UInt32(start)
        wf_row = mi.Float(0.0)
        wb_row = mi.Float(0.0)
        while dr.hint(active & (i < cnt), label="lfm light choice"):
            r = start + i
            wf, wb = self._lamp_weights(r, p, n, wi, gloss)
            w = wf + wb
            wsum += w
            take = sampler.next_float32() * wsum < w
            row = dr.select(take, r, row)
            wf_row = dr.select(take, wf, wf_row)
            wb_row = dr.select(take, wb, wb_row)
            i += 1
        beam = sampler.next_float32() * (wf_row + wb_row) < wb_row
        S = self.sets
        em = dr.select(beam, dr.gather(mi.EmitterPtr, S.beams, row, active),
                       dr.gather(mi.EmitterPtr, S.faces, row, active))
        pmf = dr.select(wsum > 0, dr.select(beam, wb_row, wf_row) / wsum, 0.0)
        slot = dr.gather(mi.UInt32, S.slot, row, active) if self.S > 1 else mi.UInt32(0)
        return em, pmf, wsum, slot

    def _set_row(self, em_ptr, lset):
        """Lamp row of emitter ``em_ptr`` in lane set ``lset`` (UInt32), whether it is the lamp's beam, whether it
        is a member at all (its light is recorded by this lane only then) and its slot (0 outside a union)."""
        mi, dr = self.mi, self.dr
        eid = dr.reinterpret_array(mi.UInt32, em_ptr)
        T = self.sets.tab
        ok = eid < self.sets.n_id
        in_g = ok & (dr.gather(mi.UInt32, T[0], eid, ok) == lset)
        in_l = ok & (dr.gather(mi.UInt32, T[3], eid, ok) == lset)
        row = dr.select(in_g, dr.gather(mi.UInt32, T[1], eid, in_g), dr.gather(mi.UInt32, T[4], eid, in_l))
        beam = dr.select(in_g, dr.gather(mi.UInt32, T[2], eid, in_g), dr.gather(mi.UInt32, T[5], eid, in_l)) == 1
        member = in_g | in_l
        slot = mi.UInt32(0)
        if self.S > 1:
            in_u = ok & (dr.gather(mi.UInt32, T[6], eid, ok) == lset)
            row = dr.select(in_u, dr.gather(mi.UInt32, T[7], eid, in_u), row)
            beam = dr.select(in_u, dr.gather(mi.UInt32, T[8], eid, in_u) == 1, beam)
            member |= in_u
            slot = dr.select(in_u, dr.gather(mi.UInt32, self.sets.slot, row, in_u), 0)
        return row, beam, member, slot

    @dr.syntax
    def _radiance(self, sampler, ray, lset, sobol=False, u_light=None):
        """Radiance (one ``mi.Spectrum`` per slot, W sr^-1 m^-2 nm^-1 at the ray's 4 wavelengths) arriving along
        ``ray`` from the emitters of light set ``lset`` (UInt32 per lane): Mitsuba's ``path`` integrator restricted
        to a set, the light of a union set's groups kept apart by slot. ``sampler``: a ``mi.PCG32`` with one
        stream per lane. ``sobol`` (Bool per lane): the first vertex's light sample (the 2-D point of
        ``sample_direction``) is ``u_light`` (Point2f) instead of the sampler's (which are drawn all the same)."""
        S = self.sets
        n_slots = self.S
        ctx = mi.BSDFContext()
        L = [mi.Spectrum(0.0) for _ in range(n_slots)]
        beta = mi.Spectrum(1.0)
        depth = mi.UInt32(0)
        active = mi.Bool(True)
        si_prev = dr.zeros(mi.SurfaceInteraction3f)
        pdf_prev = mi.Float(1.0)
        delta_prev = mi.Bool(True)
        wsum_prev = mi.Float(0.0)
        wi_prev = mi.Vector3f(0.0, 0.0, 1.0)
        ga_prev = mi.Float(0.0)
        gc_prev = mi.Float(0.0)
        cnt = dr.gather(mi.UInt32, S.count, lset)
        start = dr.gather(mi.UInt32, S.start, lset)
        while dr.hint(active, max_iterations=self.max_depth, label="lfm light-set path"):
            si = self.scene.ray_intersect(ray, ray_flags=mi.RayFlags.All, coherent=depth == 0, active=active)
            bsdf = si.bsdf(ray)
            # the glossy coat at this vertex (alpha 0: none), for the light choice (:meth:`_lamp_weights`)
            bid = dr.reinterpret_array(mi.UInt32, bsdf)
            in_t = active & si.is_valid() & (bid < self.n_gloss)
            ga = dr.gather(mi.Float, self.gloss_a, bid, in_t)
            gc = dr.gather(mi.Float, self.gloss_c, bid, in_t)
            wi_w = -ray.d
            # emission hit by the camera ray or by BSDF sampling, if the emitter is in this lane's set; its MIS
            # weight needs the probability with which the previous vertex's next-event estimation picks it
            ds = mi.DirectionSample3f(self.scene, si=si, ref=si_prev)
            # the emitter hit, as si.emitter(scene) but with the environment read from an array: Mitsuba's
            # select puts the environment's registry id into the kernel as a literal (another per scene)
            ds.emitter = dr.select(si.is_valid(), si.shape.emitter(),
                                   dr.gather(mi.EmitterPtr, self.env, 0, active))
            row_hit, beam_hit, in_set, slot_hit = self._set_row(ds.emitter, lset)
            wf_hit, wb_hit = self._lamp_weights(row_hit, si_prev.p, si_prev.n, wi_prev, (ga_prev, gc_prev))
            pmf_hit = dr.select(in_set & ~delta_prev, dr.select(beam_hit, wb_hit, wf_hit), 0.0) \
                / dr.select(wsum_prev > 0, wsum_prev, 1.0)
            em_pdf = dr.select(delta_prev, 0.0, pmf_hit * ds.emitter.pdf_direction(si_prev, ds, active & ~delta_prev))
            hit_em = active & in_set
            # emission clamped at 0 (:data:`EMISSION_FLOOR`): Mitsuba's sunsky returns slightly negative spectral
            # radiance near the horizon at low sun (dusk), which no light can have
            c_hit = beta * _mis_weight(pdf_prev, em_pdf) * dr.maximum(ds.emitter.eval(si, hit_em), EMISSION_FLOOR) \
                * dr.select(si.is_valid(), 1.0, self.sky_scale)
            L = [L[k] + (dr.select(slot_hit == k, c_hit, 0.0) if n_slots > 1 else c_hit) for k in range(n_slots)]

            active_next = active & (depth + 1 < self.max_depth) & si.is_valid()
            # next-event estimation: one emitter of this lane's set, chosen in proportion to its estimated light
            # at this point (:meth:`_choose_light`)
            active_em = active_next & mi.has_flag(bsdf.flags(), mi.BSDFFlags.Smooth)
            em, pmf_em, wsum, slot_em = self._choose_light(sampler, start, cnt, si.p, si.n, active_em, wi_w, (ga, gc))
            u_em = mi.Point2f(sampler.next_float32(), sampler.next_float32())
            if u_light is not None:
                u_em = dr.select(sobol & (depth == 0), u_light, u_em)
            ds_em, w_em = em.sample_direction(si, u_em, active_em)
            w_em = dr.maximum(w_em, EMISSION_FLOOR)  # as above: the clamped sky, an unbiased estimate of it
            w_em *= dr.select(dr.reinterpret_array(mi.UInt32, em) == self.env_id, self.sky_scale, 1.0)
            active_em &= (ds_em.pdf != 0.0) & (pmf_em > 0)
            occluded = self.scene.ray_test(si.spawn_ray_to(ds_em.p), active_em)
            active_em &= ~occluded
            wo = si.to_local(ds_em.d)
            bsdf_val, bsdf_pdf = bsdf.eval_pdf(ctx, si, wo, active_em)
            mis_em = dr.select(ds_em.delta, 1.0, _mis_weight(ds_em.pdf * pmf_em, bsdf_pdf))
            c_em = dr.select(active_em, beta * mis_em * bsdf_val * w_em / pmf_em, 0.0)
            L = [L[k] + (dr.select(slot_em == k, c_em, 0.0) if n_slots > 1 else c_em) for k in range(n_slots)]

            # continue the path by BSDF sampling
            u1 = sampler.next_float32()
            bs, bsdf_w = bsdf.sample(ctx, si, u1, mi.Point2f(sampler.next_float32(), sampler.next_float32()),
                                     active_next)
            ray = si.spawn_ray(si.to_world(bs.wo))
            beta *= bsdf_w
            # Russian roulette from vertex RR_DEPTH on (as Mitsuba's path integrator, with its rule: survive with
            # probability min(max throughput, 0.95), divide by it): unbiased, and the deep vertices of night
            # scenes (little light, much cost) are mostly skipped
            q = dr.minimum(dr.max(beta), 0.95)
            rr = active_next & (depth + 1 >= RR_DEPTH)
            survive = ~rr | (sampler.next_float32() < q)
            beta = dr.select(rr & survive, beta / dr.select(q > 0, q, 1.0), beta)
            active_next &= survive
            si_prev = dr.detach(si, True)
            pdf_prev = bs.pdf
            delta_prev = mi.has_flag(bs.sampled_type, mi.BSDFFlags.Delta)
            wsum_prev = wsum
            wi_prev = wi_w
            ga_prev = ga
            gc_prev = gc
            active = active_next & (dr.max(beta) != 0)
            depth += 1
        return L

    def hits(self, t: float, passes: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
        """First hits of camera rays at time ``t`` (s), ``passes`` jittered rays per pixel.

        Returns (registry ids of the hit shapes (passes, H, W) int64, 0 = no hit; hit points of pass 0
        (3, H, W) float32, m, world frame).
        """
        W, H = self.W, self.H
        n = W * H * passes
        lane = dr.arange(mi.UInt32, n)
        pix = lane % (W * H)
        sampler = mi.load_dict({"type": "independent"})
        sampler.seed(dr.opaque(mi.UInt32, seed), n)
        px = mi.Float(pix % W) + sampler.next_1d()
        py = mi.Float(pix // W) + sampler.next_1d()
        ray = self.camera_ray(px, py, dr.opaque(mi.Float, float(t)))
        ray.wavelengths = mi.Spectrum(550.0)
        si = self.scene.ray_intersect(ray, ray_flags=mi.RayFlags.Minimal, coherent=True)
        ids = dr.select(si.is_valid(), dr.reinterpret_array(mi.UInt32, si.shape), 0)
        dr.eval(ids, si.p)
        ids = np.asarray(ids, dtype=np.int64).reshape(passes, H, W)
        p = np.stack([np.asarray(si.p[i], dtype=np.float32).reshape(passes, H, W)[0] for i in range(3)])
        return ids, p
