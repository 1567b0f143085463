"""Simulated trials look like real ones: descriptor quantities inside the spread of the recordings.

For every recorded material, the median over simulated 2 s slides of each
quantity of paper eq. 17 (Hjorth A, M, C of PAC and of the electrodes, the
PAC/electrode correlations L and N) must lie within the 5-95 % range of the
real trials' 2 s segments, for most materials.  The full run (trials 1-30,
10 simulated trials) is in docs/simulator.md.
"""

from __future__ import annotations

import numpy as np
import pytest

from tactile_descriptors_lab.textures.validation import QUANTITIES, compare_with_recordings


@pytest.mark.realdata
def test_simulated_descriptors_fall_inside_the_real_spread(biotac_data_dir):
    res = compare_with_recordings(biotac_data_dir, trials=range(1, 6), n_sim=5, seed=3)
    assert len(res) == 20
    inside = np.array([r.inside() for r in res]).mean(axis=0)
    frac = dict(zip(QUANTITIES, inside))
    for q in ("A_pac", "M_pac", "C_pac"):
        assert frac[q] >= 0.85, frac
    for q in ("A_E", "M_E", "C_E", "L", "N"):
        assert frac[q] >= 0.7, frac
