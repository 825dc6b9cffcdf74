"""The compiled read-out of one capture on the CPU (numba; imported lazily by :mod:`lfmbench.sensor`).

One pass per capture instead of about thirteen torch element-wise passes (read noise, DSNU offset, conversion
gain, voltage swing, ADC, saturation flag, input referral): the same float operations in the same order and the
same dtype as the torch chain of :func:`lfmbench.sensor.read_capture` and
:func:`lfmbench.sensor.simulate_split_pixel_electrons`, so both give bit-identical outputs
(``tests/sensor/test_sensor.py`` checks it). Module-level and ``cache=True`` so that DataLoader workers load it from
numba's on-disk cache (see :mod:`lfmbench.sensor._poisson_kernel`).
"""
from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, nogil=True, error_model="numpy")
def readout(n, z, rn, offset, offset_row, cg, swing, dpv, bl, max_dn, sat_v, gain_k, sub, mul, dn, e, sat,
            c):  # pragma: no cover - compiled by numba
    """Read one capture of R rows of P pixels.

    Per pixel j of row r, in the dtype of ``n`` (every scalar given in that dtype)::

        v = z * rn + n  (or n without read noise)  [+ offset[offset_row[r], j]]          e-
        v = min(v * cg, swing)                                                           V
        dn = min(max(rint(v * dpv + bl), 0), max_dn)                                     DN
        sat[r, c, j] = v >= sat_v
        e = (dn - bl) / gain_k - sub[r]  [* mul[r]]                                      e-

    Args: ``n`` (R, P) collected e-; ``z`` (R, P) standard normals, or (0, P) for no read noise; ``rn`` read
    noise e-; ``offset`` (O, P) DSNU offsets e-, or (0, P); ``offset_row`` (R,) int64 row of ``offset`` per row;
    ``cg`` conversion gain V/e-; ``swing`` V; ``dpv`` ADC gain DN/V; ``bl`` black level DN; ``max_dn`` DN;
    ``sat_v`` saturation threshold V; ``gain_k`` system gain DN/e-; ``sub`` (R,) mean dark signal e-; ``mul``
    (R,) LPD-equivalence factor (1) or (0,); ``dn``, ``e`` (R, P) and ``sat`` (R, 3, P) bool written, ``sat``
    in channel ``c``.
    """
    zero = cg - cg
    R, P = n.shape
    use_z = z.shape[0] > 0
    use_off = offset.shape[0] > 0
    use_mul = mul.shape[0] > 0
    for r in range(R):
        s = sub[r]
        f = mul[r] if use_mul else zero
        o = offset_row[r] if use_off else 0
        for j in range(P):
            v = z[r, j] * rn + n[r, j] if use_z else n[r, j]
            if use_off:
                v = v + offset[o, j]
            v = min(v * cg, swing)
            d = min(max(np.rint(v * dpv + bl), zero), max_dn)
            dn[r, j] = d
            sat[r, c, j] = v >= sat_v
            x = (d - bl) / gain_k - s
            e[r, j] = x * f if use_mul else x
