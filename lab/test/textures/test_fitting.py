"""Texture fitting: the shipped models are what fitting the real recordings gives."""

from __future__ import annotations

import numpy as np
import pytest

from tactile_descriptors_ros.sim import textures as tx


@pytest.mark.realdata
def test_fit_reproduces_the_shipped_model(biotac_data_dir):
    """The shipped JSON is exactly what fit-textures computes from the data (trials 1-30)."""
    from tactile_descriptors_lab.datasets.biotac_slide import load_recordings
    from tactile_descriptors_lab.textures.fitting import fit_material

    recs = load_recordings(biotac_data_dir, materials=[18])
    fitted = fit_material(recs, "soft_sponge")
    shipped = tx.get_material("soft_sponge")
    assert np.allclose(fitted.vibration.ar, shipped.vibration.ar, rtol=1e-9)
    assert fitted.deformation.electrode_mean == pytest.approx(shipped.deformation.electrode_mean)
