"""Shared builders for the bag tests: messages in rosbags form (no rclpy) and in rclpy form."""

from __future__ import annotations

import numpy as np
import pytest


def _time(store, t_ns: int):
    return store.types["builtin_interfaces/msg/Time"](sec=t_ns // 1_000_000_000, nanosec=t_ns % 1_000_000_000)


def _header(store, t_ns: int, frame_id: str = "biotac_index"):
    return store.types["std_msgs/msg/Header"](stamp=_time(store, t_ns), frame_id=frame_id)


def make_batch(store, stamp_ns: int, first_seq: int, frames: int = 2, pac=None, pdc=None, invalid_at=()):
    """A rosbags BioTacFrameBatch with ``frames`` frames (22 PAC samples each, 10 ms frames)."""
    cls = store.types["tactile_descriptors_msgs/msg/BioTacFrameBatch"]
    n_pac = 22 * frames
    pac = np.arange(n_pac, dtype=np.uint16) if pac is None else np.asarray(pac, dtype=np.uint16)
    for i in invalid_at:
        pac[i] = cls.INVALID_COUNT
    pdc = np.full(frames, 10, dtype=np.uint16) if pdc is None else np.asarray(pdc, dtype=np.uint16)
    return cls(
        header=_header(store, stamp_ns), sensor_name="biotac_index", body_part="index", serial_number="BT1",
        chip_select=1, first_frame_sequence=first_seq, frame_count=frames, electrode_count=19,
        pac=pac, pac_offset_ns=(np.arange(n_pac, dtype=np.int64) * 10_000_000) // 22,
        frame_offset_ns=np.arange(frames, dtype=np.int64) * 10_000_000, pdc=pdc,
        tac=np.full(frames, 2000, dtype=np.uint16), tdc=np.full(frames, 1500, dtype=np.uint16),
        electrodes=np.arange(19 * frames, dtype=np.uint16), pac_pa_per_count=0.37, pdc_pa_per_count=36.5,
        force_n_per_count=0.05, pdc_tare_counts=0.0, electrode_tare_counts=np.zeros(0), bad_words=0,
    )


def make_label(store, stamp_ns: int, name: str = "cork"):
    return store.types["tactile_descriptors_msgs/msg/Label"](header=_header(store, stamp_ns, ""), exploration_id=3,
                                                             class_name=name)


#: The labels of :func:`make_descriptor`'s values.
DESCRIPTOR_LABELS = ["thumb/A_pac", "index/A_pac", "index/M_pac"]


def make_layout(store, stamp_ns: int, labels=DESCRIPTOR_LABELS):
    """The rosbags DescriptorLayout of ``labels``."""
    from tactile_descriptors_ros.layouts import layout_id

    return store.types["tactile_descriptors_msgs/msg/DescriptorLayout"](
        header=_header(store, stamp_ns, "shadow_hand"), layout_id=layout_id(labels), robot="shadow_hand",
        layout_mode="concat", channel_mode="paper", body_parts=["thumb", "index"], labels=list(labels))


def make_descriptor(store, stamp_ns: int, inline: bool = True):
    """A rosbags Descriptor: its labels inline (a publisher without a layout topic), or only its layout's id."""
    from tactile_descriptors_ros.layouts import layout_id

    cls = store.types["tactile_descriptors_msgs/msg/Descriptor"]
    return cls(
        header=_header(store, stamp_ns, ""), robot="shadow_hand", exploration_id=4,
        window_start=_time(store, stamp_ns - 2_000_000_000), window_end=_time(store, stamp_ns),
        window_mode="exploration", layout_mode="concat", channel_mode="averaged",
        body_parts=["thumb", "index"], contact=np.array([False, True]),
        cells_in_contact=np.array([0, 1], dtype=np.uint16), cells_total=np.array([1, 1], dtype=np.uint16),
        mean_force_n=np.array([0.0, 1.25]),
        quality=np.array([cls.QUALITY_NO_CONTACT | cls.QUALITY_SHORT, cls.QUALITY_INVALID | 1024], dtype=np.uint32),
        layout_id=layout_id(DESCRIPTOR_LABELS), labels=list(DESCRIPTOR_LABELS) if inline else [],
        values=np.array([0.0, 1500.0, 310.5]),
    )


def make_prediction(store, stamp_ns: int):
    cls = store.types["tactile_descriptors_msgs/msg/Prediction"]
    return cls(
        header=_header(store, stamp_ns, ""), exploration_id=4, window_end=_time(store, stamp_ns), has_model=True,
        class_name="felt", class_names=["cork", "felt", "steel", "cotton"],
        scores=np.array([0.25, 1.5, -2.0, 1.0]), model_version=7, updates=7,
    )


@pytest.fixture
def store():
    from tactile_descriptors_ros.bags.types import tactile_typestore

    return tactile_typestore()
