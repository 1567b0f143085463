"""Write recordings in other labs' formats, so the readers can be checked against the CSV path.

Each writer takes :class:`BiotacRecording` objects (read from the shared CSV
recordings) and writes them as one format: Shadow Robot ``BiotacAll`` bags
(ROS 1 or ROS 2), UPenn ``BioTacHand`` bags (ROS 1), an HDF5 file with one
group a trial, NPZ files with one file a trial.  Frame time stamps travel as
integer ns, so the round trip is exact.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tactile_descriptors_lab.datasets.layouts import SKIN_SAMPLES_PER_FRAME, skin_columns
from tactile_descriptors_lab.datasets.msgdefs import SHADOW_ALL, UPENN_HAND, foreign_typestore
from tactile_descriptors_lab.datasets.recording import BiotacRecording


def _time(store, t_ns: int):
    return store.types["builtin_interfaces/msg/Time"](sec=int(t_ns // 1_000_000_000),
                                                      nanosec=int(t_ns % 1_000_000_000))


def _header(store, t_ns: int, seq: int, ros1: bool):
    cls = store.types["std_msgs/msg/Header"]
    if ros1:
        return cls(seq=seq, stamp=_time(store, t_ns), frame_id="rh_palm")
    return cls(stamp=_time(store, t_ns), frame_id="rh_palm")


def _shadow_msgs(store, rec: BiotacRecording, sensor: int, ros1: bool):
    biotac = store.types["sr_robot_msgs/msg/Biotac"]
    k = rec.pac_per_frame
    empty = biotac(pac0=0, pac1=0, pac=np.zeros(0, np.int16), pdc=0, tac=0, tdc=0,
                   electrodes=np.zeros(19, np.int16))
    for i in range(rec.n_frames):
        pac = rec.pac[i * k:(i + 1) * k].astype(np.int16)
        mine = biotac(pac0=int(pac[0]), pac1=int(pac[1]), pac=pac, pdc=int(rec.pdc[i]), tac=int(rec.tac[i]),
                      tdc=int(rec.tdc[i]), electrodes=rec.electrodes[:, i].astype(np.int16))
        tactiles = [mine if j == sensor else empty for j in range(5)]
        t = int(rec.frame_t_ns[i])
        yield t, store.types[SHADOW_ALL](header=_header(store, t, i, ros1), tactiles=tactiles)


def _upenn_msgs(store, rec: BiotacRecording, sensor: int):
    data = store.types["biotac_sensors/msg/BioTacData"]
    timing = store.types["biotac_sensors/msg/BioTacTime"]
    k = rec.pac_per_frame
    for i in range(rec.n_frames):
        t = int(rec.frame_t_ns[i])
        bts = []
        for j in range(sensor + 1):
            mine = j == sensor
            bts.append(data(
                bt_serial=f"BT{j:04d}", bt_position=j,
                tdc_data=int(rec.tdc[i]) if mine else 0, tac_data=int(rec.tac[i]) if mine else 0,
                pdc_data=int(rec.pdc[i]) if mine else 0,
                pac_data=(rec.pac[i * k:(i + 1) * k] if mine else np.zeros(k)).astype(np.uint16),
                electrode_data=(rec.electrodes[:, i] if mine else np.zeros(19)).astype(np.uint16)))
        bt_time = timing(frame_start_time=_time(store, t), frame_end_time=_time(store, t + 10_000_000),
                         tdc_ns_offset=0, tac_ns_offset=0, pdc_ns_offset=0,
                         pac_ns_offset=np.zeros(22, np.uint32), electrode_ns_offset=np.zeros(19, np.uint32))
        yield t, store.types[UPENN_HAND](header=_header(store, t, i, True), hand_id="left", bt_data=bts,
                                         bt_time=bt_time)


def write_ros1_bag(path: Path, rec: BiotacRecording, kind: str = "shadow", sensor: int = 0,
                   topic: str = "/rh/tactile") -> Path:
    """One trial as a ROS 1 bag of Shadow ``BiotacAll`` or UPenn ``BioTacHand`` messages."""
    from rosbags.rosbag1 import Writer

    store = foreign_typestore(ros1=True)
    msgtype = SHADOW_ALL if kind == "shadow" else UPENN_HAND
    msgs = _shadow_msgs(store, rec, sensor, True) if kind == "shadow" else _upenn_msgs(store, rec, sensor)
    path.parent.mkdir(parents=True, exist_ok=True)
    with Writer(path) as writer:
        conn = writer.add_connection(topic, msgtype, typestore=store)
        for t, msg in msgs:
            writer.write(conn, t, store.serialize_ros1(msg, msgtype))
    return path


def write_ros2_shadow_bag(path: Path, rec: BiotacRecording, sensor: int = 0, topic: str = "/rh/tactile") -> Path:
    """One trial as a ROS 2 (mcap) bag of Shadow ``BiotacAll`` messages."""
    from rosbags.rosbag2 import StoragePlugin, Writer

    store = foreign_typestore()
    path.parent.mkdir(parents=True, exist_ok=True)
    with Writer(path, version=8, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection(topic, SHADOW_ALL, typestore=store)
        for t, msg in _shadow_msgs(store, rec, sensor, False):
            writer.write(conn, t, store.serialize_cdr(msg, SHADOW_ALL))
    return path


def write_hdf5(path: Path, recs: list[BiotacRecording], names: dict[int, str]) -> Path:
    """One HDF5 file, a group ``<class name>/trial_<n>`` a trial, a dataset a channel."""
    import h5py

    with h5py.File(path, "w") as h5:
        for r in recs:
            g = h5.create_group(f"{names[r.material]}/trial_{r.trial:02d}")
            g["stamp_ns"] = r.frame_t_ns
            g["pac"] = r.pac.reshape(r.n_frames, r.pac_per_frame).astype(np.uint16)
            g["electrodes"] = r.electrodes.T.astype(np.uint16)
            for ch in ("pdc", "tac", "tdc"):
                g[ch] = getattr(r, ch).astype(np.uint16)
    return path


def write_npz(folder: Path, recs: list[BiotacRecording], names: dict[int, str]) -> Path:
    """NPZ files ``<class name>/<class name>_<trial>.npz`` holding 2-D PAC and electrode arrays."""
    for r in recs:
        d = folder / names[r.material]
        d.mkdir(parents=True, exist_ok=True)
        np.savez(d / f"{names[r.material]}_{r.trial}.npz", t=r.frame_t_ns,
                 PAC=r.pac.reshape(r.n_frames, r.pac_per_frame), E=r.electrodes.T, PDC=r.pdc, TAC=r.tac,
                 TDC=r.tdc)
    return folder


# --------------------------------------------------------------------------- skin cells

def write_skin_csv(folder: Path, trials: list[dict], force_offset: int = 0) -> Path:
    """CSV files ``<class>/trial_<n>.csv``: one row a force sample, ``acc_x1 .. acc_x4`` the accelerometer's."""
    for tr in trials:
        cols = skin_columns(tr)
        for j in range(3):
            cols[f"force{j + 1}"] = cols[f"force{j + 1}"] + force_offset
        d = folder / tr["class_name"]
        d.mkdir(parents=True, exist_ok=True)
        names = list(cols)
        lines = [",".join(names)]
        for i in range(tr["t_ns"].shape[0]):
            lines.append(",".join(repr(float(cols[c][i])) if c in ("prox", "temp_c") else str(int(cols[c][i]))
                                  for c in names))
        (d / f"trial_{tr['trial']}.csv").write_text("\n".join(lines) + "\n")
    return folder


def write_skin_npz(folder: Path, trials: list[dict]) -> Path:
    """NPZ files ``<class>_<n>.npz``: 2-D accelerometer arrays (frames, 4) per axis."""
    k = SKIN_SAMPLES_PER_FRAME
    folder.mkdir(parents=True, exist_ok=True)
    for tr in trials:
        np.savez(folder / f"{tr['class_name']}_{tr['trial']}.npz", stamp=tr["t_ns"],
                 **{f"a{axis}": tr["vibration"][row].reshape(-1, k) for row, axis in enumerate("xyz")},
                 **{f"F{j + 1}": tr["force"][j] for j in range(3)}, proximity=tr["proximity"],
                 temperature=tr["temperature"])
    return folder


#: ``sr_robot_msgs/Biotac`` of old Shadow drivers: two PAC samples a message, no ``pac`` array.
OLD_SHADOW_BIOTAC = """\
int16 pac0
int16 pac1
int16 pdc
int16 tac
int16 tdc
int16[] electrodes
"""


def write_old_shadow_bag(path: Path, rec: BiotacRecording, electrodes: bool = True, sensor: int = 0,
                         topic: str = "/rh/tactile") -> Path:
    """One trial as a ROS 1 bag of an old ``BiotacAll``: ``pac0, pac1`` only (the frame's first two PAC
    samples), with the electrodes or with an empty electrode array."""
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC)
    types = get_types_from_msg(OLD_SHADOW_BIOTAC, "sr_robot_msgs/msg/Biotac")
    types.update(get_types_from_msg("std_msgs/Header header\nsr_robot_msgs/Biotac[5] tactiles\n", SHADOW_ALL))
    store.register(types)
    biotac = store.types["sr_robot_msgs/msg/Biotac"]
    k = rec.pac_per_frame
    none = np.zeros(0, np.int16)
    empty = biotac(pac0=0, pac1=0, pdc=0, tac=0, tdc=0, electrodes=np.zeros(19, np.int16) if electrodes else none)
    path.parent.mkdir(parents=True, exist_ok=True)
    with Writer(path) as writer:
        conn = writer.add_connection(topic, SHADOW_ALL, typestore=store)
        for i in range(rec.n_frames):
            pac = rec.pac[i * k:i * k + 2]
            mine = biotac(pac0=int(pac[0]), pac1=int(pac[1]), pdc=int(rec.pdc[i]), tac=int(rec.tac[i]),
                          tdc=int(rec.tdc[i]),
                          electrodes=rec.electrodes[:, i].astype(np.int16) if electrodes else none)
            t = int(rec.frame_t_ns[i])
            msg = store.types[SHADOW_ALL](header=_header(store, t, i, True),
                                          tactiles=[mine if j == sensor else empty for j in range(5)])
            writer.write(conn, t, store.serialize_ros1(msg, SHADOW_ALL))
    return path


