"""A rosbags type store that knows the tactile messages, built from their ``.msg`` text.

rosbags computes CDR layouts and RIHS01 type hashes from message definitions
alone, so bags can be written, read and checked without rclpy.  The base
store is a ROS 2 distribution's (Kilted by default; Jazzy has the same
``std_msgs``/``builtin_interfaces`` definitions, hence the same hashes); the
``tactile_descriptors_msgs`` types are parsed from the installed share
directory (``<prefix>/share/tactile_descriptors_msgs/msg``) or, in a source
checkout, from ``msg/msg/``.  Types of other packages met while recording
(a robot's own messages) are registered on demand from their installed
``.msg`` files found through the ament index.
"""

from __future__ import annotations

import functools
import os
import sys
from collections.abc import Iterable
from pathlib import Path

from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

from ..errors import BagError

__all__ = [
    "MSG_PACKAGE",
    "TACTILE_TYPES",
    "DISTROS",
    "msg_dir",
    "tactile_typestore",
    "ensure_types",
    "msgtype_of",
    "full_msgtype",
]

#: The interface package of this project.
MSG_PACKAGE = "tactile_descriptors_msgs"

#: The project's message types (full ROS 2 names).
TACTILE_TYPES = tuple(
    f"{MSG_PACKAGE}/msg/{name}"
    for name in ("BioTacFrameBatch", "SkinPartFrames", "SkinCellFrame", "Descriptor", "DescriptorLayout", "Prediction",
                 "Label", "Contact", "ContactArray")
)

#: Base stores by distribution name.
DISTROS = {
    "humble": Stores.ROS2_HUMBLE,
    "iron": Stores.ROS2_IRON,
    "jazzy": Stores.ROS2_JAZZY,
    "kilted": Stores.ROS2_KILTED,
}


def _share_dirs() -> list[Path]:
    """Install prefixes' ``share`` directories: the ament index, then this interpreter's prefix."""
    dirs: list[Path] = []
    for prefix in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep):
        if prefix:
            dirs.append(Path(prefix) / "share")
    dirs.append(Path(sys.prefix) / "share")
    seen: set[Path] = set()
    unique = []
    for d in dirs:
        if d not in seen:
            seen.add(d)
            unique.append(d)
    return unique


def msg_dir() -> Path:
    """Directory holding the ``tactile_descriptors_msgs`` ``.msg`` files.

    Looked up in order: ``$TACTILE_MSG_DIR``; the installed share directory of
    every prefix on ``AMENT_PREFIX_PATH`` and of this interpreter; the source
    checkout (``<repo>/msg/msg``).

    Raises
    ------
    BagError
        If no directory with the project's ``.msg`` files is found.
    """
    candidates: list[Path] = []
    env = os.environ.get("TACTILE_MSG_DIR")
    if env:
        candidates.append(Path(env))
    candidates += [d / MSG_PACKAGE / "msg" for d in _share_dirs()]
    candidates.append(Path(__file__).resolve().parents[2] / "msg" / "msg")
    for path in candidates:
        if (path / "BioTacFrameBatch.msg").is_file():
            return path
    raise BagError(
        f"cannot find the {MSG_PACKAGE} .msg files (looked in {', '.join(map(str, candidates))}); "
        "set TACTILE_MSG_DIR"
    )


@functools.lru_cache(maxsize=8)
def _cached_store(distro: str, directory: str) -> Typestore:
    store = get_typestore(DISTROS[distro])
    types = {}
    for path in sorted(Path(directory).glob("*.msg")):
        types.update(get_types_from_msg(path.read_text(), f"{MSG_PACKAGE}/msg/{path.stem}"))
    missing = [t for t in TACTILE_TYPES if t not in types]
    if missing:
        raise BagError(f"{directory}: message definitions missing for {missing}")
    store.register(types)
    return store


def tactile_typestore(distro: str = "kilted") -> Typestore:
    """A rosbags type store of ``distro`` with the tactile message types registered.

    Parameters
    ----------
    distro : {"kilted", "jazzy", "iron", "humble"}
        Base distribution store.  Humble bags carry no type hashes, but the
        store still computes RIHS01 hashes from the definitions.

    Returns
    -------
    rosbags.typesys.store.Typestore
        Cached per distribution; :func:`ensure_types` may add types to it.
    """
    if distro not in DISTROS:
        raise BagError(f"unknown ROS 2 distribution {distro!r} (known: {', '.join(DISTROS)})")
    return _cached_store(distro, str(msg_dir()))


def full_msgtype(msgtype: str) -> str:
    """``"std_msgs/Header"`` -> ``"std_msgs/msg/Header"``; full names are returned as they are."""
    parts = msgtype.split("/")
    if len(parts) == 2:
        return f"{parts[0]}/msg/{parts[1]}"
    if len(parts) == 3:
        return msgtype
    raise BagError(f"not a message type name: {msgtype!r} (expected pkg/msg/Name)")


def _find_msg_file(msgtype: str) -> Path | None:
    pkg, kind, name = full_msgtype(msgtype).split("/")
    for share in _share_dirs():
        path = share / pkg / kind / f"{name}.msg"
        if path.is_file():
            return path
    try:  # a colcon workspace or a system install known to the ament index only
        from ament_index_python.packages import get_package_share_directory

        path = Path(get_package_share_directory(pkg)) / kind / f"{name}.msg"
        if path.is_file():
            return path
    except Exception:  # noqa: BLE001 - ament_index absent or package unknown
        pass
    return None


def ensure_types(store: Typestore, msgtypes: Iterable[str], msgdefs: dict[str, str] | None = None) -> None:
    """Register in ``store`` every type of ``msgtypes`` it does not know yet.

    A definition is taken from ``msgdefs`` (``msgtype -> ros2msg text`` as
    found in a bag, with ``MSG:`` sections for dependencies) when given,
    otherwise from the installed ``<share>/<pkg>/msg/<Name>.msg``.
    Dependencies are registered recursively.

    Raises
    ------
    BagError
        If a definition cannot be found.
    """
    msgdefs = msgdefs or {}
    for msgtype in msgtypes:
        _ensure_one(store, full_msgtype(msgtype), msgdefs, depth=0)


def _ensure_one(store: Typestore, msgtype: str, msgdefs: dict[str, str], depth: int) -> None:
    if msgtype in store.fielddefs:
        return
    if depth > 64:
        raise BagError(f"message type dependencies of {msgtype} nest too deeply (cycle?)")
    if msgdefs.get(msgtype, "").strip():
        types = _types_from_bag_msgdef(msgtype, msgdefs[msgtype])
    else:
        path = _find_msg_file(msgtype)
        if path is None:
            raise BagError(
                f"no definition for message type {msgtype}: not in the bag and no "
                f"{msgtype.split('/')[-1]}.msg installed (source its workspace first)"
            )
        types = dict(get_types_from_msg(path.read_text(), msgtype))
    for _consts, fields in types.values():
        for _fname, desc in fields:
            for dep in _nested_names(desc):
                if dep not in types:
                    _ensure_one(store, dep, msgdefs, depth + 1)
    store.register({name: spec for name, spec in types.items() if name not in store.fielddefs})


def _nested_names(desc: tuple) -> list[str]:
    kind, rest = desc
    if kind.name == "NAME":
        return [full_msgtype(rest)]
    if kind.name in ("ARRAY", "SEQUENCE"):
        return _nested_names(rest[0])
    return []


def _types_from_bag_msgdef(msgtype: str, text: str) -> dict:
    """Parse a ``ros2msg`` definition as rosbag2 stores it (main type, then ``MSG:`` sections)."""
    separator = "=" * 80 + "\n"
    sections = text.split(separator)
    types = dict(get_types_from_msg(sections[0], msgtype))
    for section in sections[1:]:
        header, _, body = section.partition("\n")
        if not header.startswith("MSG: "):
            raise BagError(f"unexpected message definition section {header!r} for {msgtype}")
        types.update(get_types_from_msg(body, full_msgtype(header[5:].strip())))
    return types


def msgtype_of(message: object) -> str:
    """Full ROS 2 type name of a rosbags or rclpy message object."""
    name = getattr(message, "__msgtype__", None)
    if name:
        return str(name)
    module = type(message).__module__.split(".")  # rclpy: "<pkg>.msg._<name>"
    if len(module) >= 2 and module[1] in ("msg", "srv", "action"):
        return f"{module[0]}/{module[1]}/{type(message).__name__}"
    raise BagError(f"cannot tell the ROS type of {type(message).__name__}")
