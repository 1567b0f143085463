"""Block averaging on real BioTac windows: known answers through the lab's recording reader."""

from __future__ import annotations

import numpy as np
import pytest

from tactile_descriptors_ros.core.aggregation import describe_window
from tactile_descriptors_ros.core.blocks import block_mean, describe_blocks, split_cells

# Frames 37..386 (3.5 s) of material 1 (carpet_net), trial 3: the paper group averaged over 6 blocks of
# 1 s at most 0.5 s apart, as the evaluation computed it before block averaging moved into the core.
KNOWN_PAPER = np.array([5.5071855140152529e+03, 9.9896133974198555e+00, 3.7902145852693894e+02,
                        8.2012884021202751e+01, 7.2475357629644206e+00, 2.0147761230601371e+00,
                        5.0769268364681895e-02, 4.2195258866687936e-02])
KNOWN_LEVELS_E1_E6 = np.array([24.209999999999997, 2.456666666666667, 6.258333333333333, 6.636666666666667,
                               2.275, 6.5200000000000005])


@pytest.fixture(scope="module")
def finger():
    from tactile_descriptors_lab.datasets.biotac_slide import load_recordings
    from tactile_descriptors_lab.evaluation.bank import finger_robot, recording_cells

    return finger_robot(), recording_cells, load_recordings


@pytest.mark.realdata
def test_block_average_of_a_real_window_is_the_known_answer(finger, biotac_data_dir):
    robot, recording_cells, load_recordings = finger
    rec = load_recordings(biotac_data_dir, trials=[3], materials=[1])[0]
    cells = recording_cells(rec.crop_frames(37, 37 + 350))
    kw = {"block_s": 1.0, "block_hop_s": 0.5, "layout": "concat", "force_threshold_n": -np.inf}
    paper = describe_blocks(robot, cells, groups=("paper",), **kw)
    assert paper.extra["blocks"] == 6
    np.testing.assert_allclose(paper.values, KNOWN_PAPER, rtol=1e-12)
    levels = describe_blocks(robot, cells, groups=("levels",), **kw)
    np.testing.assert_allclose(levels.values[:6], KNOWN_LEVELS_E1_E6, rtol=1e-12)
    # the mean of the blocks' own descriptors, Activity in log: block 2 alone is not the answer
    blocks = split_cells(cells, 1.0, 0.5)
    assert [b[0].deformation.shape[1] for b in blocks] == [100] * 6
    rows = np.stack([describe_window(robot, b, groups=("paper",), layout="concat",
                                     force_threshold_n=-np.inf).values for b in blocks])
    np.testing.assert_array_equal(block_mean(rows, paper.labels), paper.values)
    assert not np.allclose(rows[1], paper.values, rtol=1e-3)


@pytest.mark.realdata
def test_a_window_shorter_than_a_block_is_one_block_bit_for_bit(finger, biotac_data_dir):
    robot, recording_cells, load_recordings = finger
    rec = load_recordings(biotac_data_dir, trials=[3], materials=[1])[0]
    cells = recording_cells(rec.crop_frames(5, 85))
    one = describe_blocks(robot, cells, block_s=1.0, block_hop_s=0.5, groups=("paper", "levels"))
    whole = describe_window(robot, cells, groups=("paper", "levels"))
    assert one.extra["blocks"] == 1
    np.testing.assert_array_equal(one.values, whole.values)
