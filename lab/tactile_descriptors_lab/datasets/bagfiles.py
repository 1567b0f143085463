"""Read BioTac trials from ROS 1 and ROS 2 bags (rosbags; no ROS installation needed).

Three message types are understood:

* ``sr_robot_msgs/BiotacAll`` (Shadow Robot): one frame a message from the
  BioTac ``sensor`` (0..4) of ``tactiles``; PAC is the ``pac`` array (every
  sample since the last message) or, in older definitions, ``pac0, pac1``;
* ``biotac_sensors/BioTacHand`` (UPenn): one frame a message from
  ``bt_data[sensor]`` (22 PAC samples, 19 electrodes);
* this package's ``BioTacFrameBatch`` with ``Label`` messages: a bag written
  by ``tactile import`` (its trials are listed in the bag's metadata) or
  recorded live (a trial ends at each label).

A Shadow or UPenn bag is one trial; its class and trial come from the
mapping's rules applied to the bag's folder or file name, or an option.
Frame stamps are the messages' ``header.stamp`` (the log time when a stamp
is zero); each frame's PAC samples are spread over the frame's interval.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from tactile_descriptors_lab.datasets.msgdefs import SHADOW_ALL, UPENN_HAND, foreign_typestore
from tactile_descriptors_lab.datasets.recording import N_ELECTRODES
from tactile_descriptors_lab.datasets.tables import natural_key
from tactile_descriptors_ros.errors import DataFormatError

__all__ = ["is_bag", "find_bags", "read_bag_frames", "BATCH_TYPE", "LABEL_TYPE", "TRIALS_KEY"]

BATCH_TYPE = "tactile_descriptors_msgs/msg/BioTacFrameBatch"
LABEL_TYPE = "tactile_descriptors_msgs/msg/Label"
#: Bag metadata key (``custom_data``) listing an imported bag's trials as JSON.
TRIALS_KEY = "tactile.trials"


def is_bag(path: Path) -> bool:
    """A ROS 1 bag file or a rosbag2 folder."""
    return (path.is_file() and path.suffix == ".bag") or (path.is_dir() and (path / "metadata.yaml").is_file())


def find_bags(root: Path, pattern: str | None) -> list[Path]:
    """Bags at or below ``root``: ``root`` itself, or those matching ``pattern`` (default every bag)."""
    if is_bag(root):
        return [root]
    if not root.is_dir():
        if root.is_file():
            raise DataFormatError(f"{root}: not a bag (a ROS 1 .bag file or a rosbag2 folder with metadata.yaml)")
        raise DataFormatError(f"{root}: no such file or folder")
    found = sorted({p for p in root.glob(pattern or "**/*") if is_bag(p)}, key=lambda p: natural_key(str(p)))
    if not found:
        raise DataFormatError(f"{root}: no bags found (ROS 1 .bag files or rosbag2 folders)")
    return found


def _stamp_ns(stamp: Any) -> int:
    sec = getattr(stamp, "sec", None)
    if sec is None:
        sec = stamp.secs if hasattr(stamp, "secs") else 0
    nsec = getattr(stamp, "nanosec", None)
    if nsec is None:
        nsec = getattr(stamp, "nsecs", 0)
    return int(sec) * 1_000_000_000 + int(nsec)


def _open(path: Path):
    from rosbags.highlevel import AnyReader
    from rosbags.highlevel.anyreader import AnyReaderError

    from tactile_descriptors_ros.bags.types import tactile_typestore

    store = foreign_typestore()
    store.register({k: v for k, v in tactile_typestore().fielddefs.items() if k.startswith("tactile_")})
    try:
        reader = AnyReader([path], default_typestore=store)
        reader.open()
    except (AnyReaderError, OSError, ValueError, KeyError) as exc:
        raise DataFormatError(f"{path}: not a readable bag ({str(exc).splitlines()[0] if str(exc) else exc!r})") \
            from None
    return reader


def _custom_data(path: Path) -> dict[str, str]:
    meta = path / "metadata.yaml"
    if not meta.is_file():
        return {}
    import yaml

    try:
        info = yaml.safe_load(meta.read_text(encoding="utf-8"))["rosbag2_bagfile_information"]
    except (yaml.YAMLError, KeyError, TypeError, UnicodeDecodeError):
        return {}
    return dict(info.get("custom_data") or {})


def read_bag_frames(path: Path, sensor: int = 0, topic: str | None = None) -> list[dict[str, Any]]:
    """Frames of one bag as trial dictionaries.

    Returns
    -------
    list of dict
        Each with ``frame_t_ns`` (n,), ``pac`` (n, k), ``pdc``, ``tac``,
        ``tdc`` (n,), ``electrodes`` (19, n), ``pac_t_ns`` (n * k or None),
        ``label`` (class name from the bag, or None), ``trial`` (or None),
        ``where`` and ``absent`` (``e1`` .. ``e19`` when the messages carry
        no electrodes, as some old Shadow drivers'; their values are zeros).  A Shadow or UPenn bag gives one; an imported or
        recorded ``BioTacFrameBatch`` bag one per trial.

    Raises
    ------
    DataFormatError
        For a bag with no BioTac topic, a sensor index out of range, or
        frames whose PAC sample count or electrode count varies.
    """
    reader = _open(path)
    try:
        conns = [c for c in reader.connections if c.msgtype in (SHADOW_ALL, UPENN_HAND, BATCH_TYPE)]
        if topic is not None:
            conns = [c for c in conns if c.topic == topic]
        if not conns:
            have = sorted({f"{c.topic} ({c.msgtype})" for c in reader.connections})
            raise DataFormatError(
                f"{path}: no {SHADOW_ALL}, {UPENN_HAND} or BioTacFrameBatch topic"
                f"{'' if topic is None else f' named {topic}'}; the bag has: {', '.join(have) or 'nothing'}")
        topics = sorted({c.topic for c in conns})
        if len(topics) > 1:
            raise DataFormatError(f"{path}: several BioTac topics {topics}: choose one (mapping key topic)")
        msgtype = conns[0].msgtype
        if msgtype == BATCH_TYPE:
            labels = [c for c in reader.connections if c.msgtype == LABEL_TYPE]
            return _read_batches(reader, conns, labels, path)
        return [_read_frames(reader, conns, msgtype, sensor, path)]
    finally:
        reader.close()


def _read_frames(reader, conns, msgtype: str, sensor: int, path: Path) -> dict[str, Any]:
    t, pac, pdc, tac, tdc, ele = [], [], [], [], [], []
    no_electrodes = False
    where = f"{path}#{conns[0].topic}"
    for i, (conn, log_ns, raw) in enumerate(reader.messages(connections=conns)):
        msg = reader.deserialize(raw, conn.msgtype)
        stamp = _stamp_ns(msg.header.stamp) or int(log_ns)
        if msgtype == SHADOW_ALL:
            if sensor >= len(msg.tactiles):
                raise DataFormatError(f"{where}: sensor {sensor} (mapping key sensor) but messages hold "
                                      f"{len(msg.tactiles)} BioTacs")
            b = msg.tactiles[sensor]
            samples = getattr(b, "pac", None)
            p = np.asarray(samples, dtype=np.int64) if samples is not None and len(samples) else \
                np.array([b.pac0, b.pac1], dtype=np.int64)
            e = np.asarray(b.electrodes, dtype=np.int64)
            d, a, c = b.pdc, b.tac, b.tdc
        else:
            if sensor >= len(msg.bt_data):
                raise DataFormatError(f"{where}: sensor {sensor} (mapping key sensor) but message {i} holds "
                                      f"{len(msg.bt_data)} BioTacs")
            b = msg.bt_data[sensor]
            p = np.asarray(b.pac_data, dtype=np.int64)
            e = np.asarray(b.electrode_data, dtype=np.int64)
            d, a, c = b.pdc_data, b.tac_data, b.tdc_data
        if pac and p.shape[0] != pac[0].shape[0]:
            raise DataFormatError(f"{where}: message {i} has {p.shape[0]} PAC samples, the first had "
                                  f"{pac[0].shape[0]}: frames of varying PAC length cannot be windowed")
        if e.shape[0] == 0 and not ele:
            no_electrodes = True  # an old driver's messages without electrodes: absent, not zero
        if no_electrodes and e.shape[0] == 0:
            e = np.zeros(N_ELECTRODES, dtype=np.int64)
        elif e.shape[0] != N_ELECTRODES or no_electrodes:
            raise DataFormatError(f"{where}: message {i} has {e.shape[0]} electrodes, not "
                                  f"{0 if no_electrodes else N_ELECTRODES} as the first")
        t.append(stamp)
        pac.append(p)
        pdc.append(int(d))
        tac.append(int(a))
        tdc.append(int(c))
        ele.append(e)
    if not t:
        raise DataFormatError(f"{where}: no messages")
    return {"frame_t_ns": np.array(t, dtype=np.int64), "pac": np.stack(pac), "pac_t_ns": None,
            "pdc": np.array(pdc, dtype=np.int64), "tac": np.array(tac, dtype=np.int64),
            "tdc": np.array(tdc, dtype=np.int64), "electrodes": np.stack(ele, axis=1),
            "label": None, "trial": None, "where": where,
            "absent": tuple(f"e{j + 1}" for j in range(N_ELECTRODES)) if no_electrodes else ()}


def _read_batches(reader, conns, label_conns, path: Path) -> list[dict[str, Any]]:
    """Frames of ``BioTacFrameBatch`` messages, cut into trials by the bag's trial list or its labels."""
    seqs, t, pac, pac_t, pdc, tac, tdc, ele, log = [], [], [], [], [], [], [], [], []
    labels: list[tuple[int, str]] = []
    k = None
    for conn, log_ns, raw in reader.messages(connections=list(conns) + list(label_conns)):
        msg = reader.deserialize(raw, conn.msgtype)
        if conn.msgtype == LABEL_TYPE:
            labels.append((int(log_ns), str(msg.class_name)))
            continue
        n = int(msg.frame_count)
        stamp = _stamp_ns(msg.header.stamp)
        per = len(msg.pac) // n if n else 0
        if n == 0 or per * n != len(msg.pac):
            raise DataFormatError(f"{path}: a batch of {n} frames holds {len(msg.pac)} PAC samples")
        if k is not None and per != k:
            raise DataFormatError(f"{path}: PAC samples per frame change from {k} to {per}")
        k = per
        seqs.append(int(msg.first_frame_sequence) + np.arange(n, dtype=np.int64))
        t.append(stamp + np.asarray(msg.frame_offset_ns, dtype=np.int64))
        pac.append(np.asarray(msg.pac, dtype=np.int64).reshape(n, per))
        pac_t.append(stamp + np.asarray(msg.pac_offset_ns, dtype=np.int64))
        pdc.append(np.asarray(msg.pdc, dtype=np.int64))
        tac.append(np.asarray(msg.tac, dtype=np.int64))
        tdc.append(np.asarray(msg.tdc, dtype=np.int64))
        ele.append(np.asarray(msg.electrodes, dtype=np.int64).reshape(n, N_ELECTRODES))
        log.append(np.full(n, int(log_ns), dtype=np.int64))
    if not t:
        raise DataFormatError(f"{path}: no BioTacFrameBatch messages")
    seq, ft, pc, pt = np.concatenate(seqs), np.concatenate(t), np.concatenate(pac), np.concatenate(pac_t)
    pd, ta, td, el, lg = (np.concatenate(x) for x in (pdc, tac, tdc, ele, log))
    listed = _custom_data(path).get(TRIALS_KEY)
    cuts: list[tuple[np.ndarray, str, int | None]] = []
    if listed:
        try:
            entries = json.loads(listed)
        except json.JSONDecodeError:
            raise DataFormatError(f"{path}: metadata {TRIALS_KEY} is not JSON") from None
        for e in entries:
            sel = np.flatnonzero((seq >= e["first_frame"]) & (seq < e["first_frame"] + e["frames"]))
            if sel.shape[0] != e["frames"]:
                raise DataFormatError(f"{path}: trial {e['class_name']} {e['trial']} lists {e['frames']} frames, "
                                      f"the bag holds {sel.shape[0]}")
            cuts.append((sel, str(e["class_name"]), int(e["trial"])))
    else:
        if not labels:
            raise DataFormatError(f"{path}: BioTac frames but no Label messages: the class of its frames is unknown")
        prev = -1
        for log_ns, name in labels:
            sel = np.flatnonzero((lg > prev) & (lg <= log_ns))
            prev = log_ns
            if sel.size:
                cuts.append((sel, name, None))
    out = []
    for i, (sel, name, trial) in enumerate(cuts):
        out.append({"frame_t_ns": ft[sel], "pac": pc[sel], "pac_t_ns": pt.reshape(-1, k)[sel].ravel(),
                    "pdc": pd[sel], "tac": ta[sel], "tdc": td[sel], "electrodes": el[sel].T.copy(),
                    "label": name, "trial": trial,
                    "where": f"{path}#{conns[0].topic}@{i + 1}"})
    return out
