"""Physical constants used across lfmbench, each defined once with its provenance.

Import from here instead of re-typing a number (``from lfmbench.constants import PLANCK_J_S``).

References
----------
.. [CODATA2018] E. Tiesinga, P. J. Mohr, D. B. Newell, B. N. Taylor, "CODATA recommended values of the
   fundamental physical constants: 2018", Rev. Mod. Phys. 93, 025010 (2021). Since the 2019 SI redefinition
   h, c and e are exact by definition.
.. [SI2019] BIPM, "The International System of Units (SI)", 9th edition (2019): K_cd = 683 lm/W exactly
   (luminous efficacy of monochromatic radiation of frequency 540e12 Hz).
.. [CIE015] CIE 015:2018 "Colorimetry", 4th ed.: K_m = 683.002 lm/W is the maximum luminous efficacy of the
   photopic V(lambda) curve (peak at 555 nm), the value colour-science also uses (``colour.constants.CONSTANT_K_M``).
.. [AIRY] M. Born and E. Wolf, "Principles of Optics", 7th ed. (1999), section 8.5.2: the first zero of the
   Airy pattern of a circular aperture lies at x = j_{1,1} = 3.8317..., i.e. r = 1.21967 lambda N.
"""
from __future__ import annotations

import math

#: Planck constant h in J s (exact, [CODATA2018]).
PLANCK_J_S: float = 6.62607015e-34

#: Speed of light in vacuum c in m/s (exact, [CODATA2018]).
SPEED_OF_LIGHT_M_PER_S: float = 299792458.0

#: Elementary charge e in C (exact, [CODATA2018]).
ELEMENTARY_CHARGE_C: float = 1.602176634e-19

#: Boltzmann constant k_B in J/K (exact, [CODATA2018]).
BOLTZMANN_J_PER_K: float = 1.380649e-23

#: h * c in J m: photon energy times wavelength, E_photon = h c / lambda ([CODATA2018]).
PLANCK_TIMES_C_J_M: float = PLANCK_J_S * SPEED_OF_LIGHT_M_PER_S

#: Luminous efficacy K_cd of 540 THz radiation in lm/W (exact SI defining constant, [SI2019]).
LUMINOUS_EFFICACY_KCD_LM_PER_W: float = 683.0

#: Maximum photopic luminous efficacy K_m in lm/W ([CIE015]); use with the CIE V(lambda) curve.
MAX_LUMINOUS_EFFICACY_KM_LM_PER_W: float = 683.002

#: Metres per nanometre (unit conversion, exact).
M_PER_NM: float = 1e-9

#: First zero of the Bessel function J1, j_{1,1} (dimensionless, [AIRY]); Airy first dark ring at
#: r = j_{1,1} / pi * lambda * N.
BESSEL_J1_FIRST_ZERO: float = 3.8317059702075125

#: Airy first-zero factor j_{1,1} / pi = 1.21967 (the familiar "1.22", [AIRY]).
AIRY_FIRST_ZERO_FACTOR: float = BESSEL_J1_FIRST_ZERO / math.pi

__all__ = [
    "PLANCK_J_S",
    "SPEED_OF_LIGHT_M_PER_S",
    "ELEMENTARY_CHARGE_C",
    "BOLTZMANN_J_PER_K",
    "PLANCK_TIMES_C_J_M",
    "LUMINOUS_EFFICACY_KCD_LM_PER_W",
    "MAX_LUMINOUS_EFFICACY_KM_LM_PER_W",
    "M_PER_NM",
    "BESSEL_J1_FIRST_ZERO",
    "AIRY_FIRST_ZERO_FACTOR",
    "POISSON_EXACT_LIMIT",
]

#: Poisson means from 2^52 on are drawn as a rounded normal by :mod:`lfmbench.sensor.poisson` and its compiled kernel
#: :mod:`lfmbench.sensor._poisson_kernel`: float64 no longer holds every count exactly there, and integer candidates
#: overflow int64 further up (``torch.poisson`` returns -2^63 for a mean of 1e20). Electrons (e-).
POISSON_EXACT_LIMIT: float = 2.0 ** 52
