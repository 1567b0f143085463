"""A hand-made ``Descriptor`` message for the classifier node's tests (importable from any test folder:
pytest puts ``test/`` on ``sys.path`` for its ``conftest.py``)."""

from __future__ import annotations

import numpy as np

__all__ = ["LABELS", "descriptor_msg"]

#: The paper's 8 values of one finger (eq. 17), as the window node labels them.
LABELS = [f"index/{n}" for n in ("A_pac", "M_pac", "C_pac", "A_pdc", "M_pdc", "C_pdc", "L_cor", "N_cor")]


def descriptor_msg(eid: int, rng: np.random.Generator):
    """Exploration ``eid``'s descriptor: one finger in contact, a 2 s window ending at ``10 eid + 2`` s,
    random positive values (Activity values are logged)."""
    from tactile_descriptors_msgs.msg import Descriptor

    msg = Descriptor()
    msg.robot = "shadow_hand"
    msg.exploration_id = eid
    msg.window_mode = Descriptor.WINDOW_EXPLORATION
    msg.layout_mode = Descriptor.MODE_CONCAT
    msg.channel_mode = Descriptor.CHANNELS_AVERAGED
    msg.window_start.sec = 10 * eid
    msg.window_end.sec = 10 * eid + 2
    msg.header.stamp = msg.window_end
    msg.body_parts = ["index"]
    msg.contact = [True]
    msg.cells_in_contact = [1]
    msg.cells_total = [1]
    msg.mean_force_n = [2.0]
    msg.quality = [0]
    msg.labels = LABELS
    msg.values = rng.uniform(0.5, 5.0, len(LABELS)).tolist()
    return msg
