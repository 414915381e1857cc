"""Loaded-tyre modes (docs/physics.md §6 ground_contact) against the §7 verification values."""

import math

import numpy as np

from ringfit.params import table9
from ringfit.physics.loaded import loaded_natural_frequencies, patch_overlap
from ringfit.physics.natural import natural_frequencies

COS_7 = [110.8, 128.9, 153.2, 181.3, 211.6, 243.7, 277.1]  # docs/physics.md §7
SIN_7 = [107.2, 121.1, 142.8, 169.0, 198.3, 229.6, 262.5]


def test_section7_values():
    g, r = table9()
    c, s = loaded_natural_frequencies(r, g, math.radians(11.69))
    np.testing.assert_allclose(np.asarray(c)[:7], COS_7, atol=0.06)
    np.testing.assert_allclose(np.asarray(s)[:7], SIN_7, atol=0.06)


def test_no_patch_is_eq18():
    g, r = table9()
    c, s = loaded_natural_frequencies(r, g, 0.0, n_max=12)
    f = np.asarray(natural_frequencies(r, g, np.arange(1, 13.0)))
    np.testing.assert_allclose(c, f, rtol=1e-12)
    np.testing.assert_allclose(s, f, rtol=1e-12)


def test_overlap_by_quadrature():
    a = math.radians(13.0)
    cc, ss = patch_overlap(a, 6)
    phi = np.linspace(-a, a, 20001)
    for i in (1, 3, 6):
        for j in (1, 2, 5):
            qc = np.trapezoid(np.cos(i * phi) * np.cos(j * phi), phi)
            qs = np.trapezoid(np.sin(i * phi) * np.sin(j * phi), phi)
            assert abs(float(cc[i - 1, j - 1]) - qc) < 1e-8
            assert abs(float(ss[i - 1, j - 1]) - qs) < 1e-8
