"""Typed access to parsed YAML that names the dotted key and the file in every error (pure, no ROS).

Shared by the robot description parser (:mod:`tactile_descriptors_ros.core.robot`,
raising :class:`~tactile_descriptors_ros.errors.ConfigError`) and the scene
parser (:mod:`tactile_descriptors_ros.sim.scene`, raising
:class:`~tactile_descriptors_ros.errors.SceneError`): the error class is a
parameter of :class:`YamlReader`.
"""

from __future__ import annotations

import math
import os
import sys
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Any

from ..errors import ConfigError

__all__ = ["YamlReader", "kind_names", "resolve_yaml", "config_dir"]

#: Where a source checkout and an installed prefix keep the config directory (resolved once: the
#: module's file does not move while it runs, and config_dir() is on the describe path of the rocket group).
_CHECKOUT_CONFIG = Path(__file__).resolve().parents[2] / "config"
_PREFIX_CONFIG = Path(sys.prefix) / "share" / "tactile_descriptors_ros" / "config"


def _kinds(kind: Any) -> tuple:
    return kind if isinstance(kind, tuple) else (kind,)


def kind_names(kind: type | tuple[type, ...]) -> str:
    """``int`` -> ``"int"``, ``(int, float)`` -> ``"int or float"`` (for "expected ..." messages)."""
    return " or ".join(k.__name__ for k in _kinds(kind))


class YamlReader:
    """One mapping of a YAML document; remembers which keys were read.

    Parameters
    ----------
    data : Any
        The mapping (anything else raises ``error``).
    key : str
        Dotted path of ``data`` in the document (``""`` for the root).
    source : str
        File (or ``"<dict>"``) named in errors.
    error : type of ConfigError
        Class of the errors raised (``ConfigError`` or a subclass).
    kind_name : callable
        Names an expected type (or tuple of types) in "expected ..., got ..." errors.
    """

    def __init__(self, data: Any, key: str, source: str, *, error: type[ConfigError] = ConfigError,
                 kind_name: Callable[[Any], str] = kind_names) -> None:
        if not isinstance(data, Mapping):
            raise error(f"expected a mapping, got {type(data).__name__}", key=key or "<root>", source=source)
        self.data = data
        self.key = key
        self.source = source
        self.error_class = error
        self.kind_name = kind_name
        self.used: set[str] = set()

    def path(self, name: str) -> str:
        """Dotted path of ``name`` below this mapping."""
        return f"{self.key}.{name}" if self.key else name

    def error(self, name: str, message: str) -> ConfigError:
        """An error (of the reader's class) about key ``name``, to raise."""
        return self.error_class(message, key=self.path(name), source=self.source)

    def reader(self, data: Any, key: str) -> YamlReader:
        """A reader of ``data`` at dotted path ``key``, same source and error class."""
        return YamlReader(data, key, self.source, error=self.error_class, kind_name=self.kind_name)

    def get(self, name: str, default: Any = ..., kind: type | tuple[type, ...] | None = None) -> Any:
        """Value of ``name`` (``default`` when missing; required when no default), checked against ``kind``.

        A ``bool`` is accepted only where ``bool`` is one of the kinds (YAML's
        ``true`` is not a number).
        """
        self.used.add(name)
        if name not in self.data:
            if default is ...:
                raise self.error(name, "required key is missing")
            return default
        value = self.data[name]
        if kind is not None and (not isinstance(value, kind) or (isinstance(value, bool) and bool not in _kinds(kind))):
            raise self.error(name, f"expected {self.kind_name(kind)}, got {value!r}")
        return value

    def number(self, name: str, default: Any = ..., *, positive: bool = False, minimum: float | None = None) -> float:
        """A finite number (int or float, not bool) as float, optionally positive or at least ``minimum``."""
        value = float(self.get(name, default, (int, float)))
        if not math.isfinite(value):
            raise self.error(name, f"must be finite, got {value!r}")
        if positive and value <= 0:
            raise self.error(name, f"must be positive, got {value!r}")
        if minimum is not None and value < minimum:
            raise self.error(name, f"must be at least {minimum}, got {value!r}")
        return value

    def child(self, name: str, default: Any = ...) -> YamlReader:
        """A reader of the mapping under ``name``."""
        return self.reader(self.get(name, default), self.path(name))

    def check_unknown(self, known: Iterable[str] = ()) -> None:
        """Raise on the first (sorted) key that was neither read nor is in ``known``."""
        allowed = self.used | set(known)
        unknown = sorted(set(self.data) - allowed)
        if unknown:
            raise self.error(unknown[0], f"unknown key (known here: {', '.join(sorted(allowed))})")


def resolve_yaml(name_or_path: str | os.PathLike[str], folder: Path, *, noun: str, file_noun: str,
                 error: type[ConfigError] = ConfigError) -> Path:
    """Resolve a shipped file's name (``"nao"`` -> ``folder/nao.yaml``) or return a YAML path as it is.

    Parameters
    ----------
    name_or_path : str or path
        A bare name, or a path (anything ending in .yaml/.yml or holding a separator).
    folder : Path
        Where the shipped files live.
    noun, file_noun : str
        How errors name the thing (``"robot"``) and its file (``"robot description file"``).
    error : type of ConfigError
        Raised for a missing file or an unknown name; the message lists the known names.
    """
    text = os.fspath(name_or_path)
    path = Path(text)
    if path.suffix in {".yaml", ".yml"} or os.sep in text:
        if not path.is_file():
            raise error(f"{file_noun} not found: {path}")
        return path
    candidate = folder / f"{text}.yaml"
    if not candidate.is_file():
        known = ", ".join(sorted(p.stem for p in folder.glob("*.yaml")))
        raise error(f"unknown {noun} {text!r} (known: {known})")
    return candidate


def config_dir() -> Path:
    """Directory holding the shipped robot descriptions and scenes.

    Looked up in order: ``$TACTILE_CONFIG_DIR``; the source checkout
    (``<repo>/config``); the installed share directory
    (``<prefix>/share/tactile_descriptors_ros/config``); the ament index.
    """
    env = os.environ.get("TACTILE_CONFIG_DIR")
    candidates = [Path(env)] if env else []
    candidates += [_CHECKOUT_CONFIG, _PREFIX_CONFIG]
    for path in candidates:
        if (path / "shadow_hand.yaml").is_file():
            return path
    try:  # a colcon install on a real ROS 2 system
        from ament_index_python.packages import get_package_share_directory

        return Path(get_package_share_directory("tactile_descriptors_ros")) / "config"
    except Exception:  # noqa: BLE001 - ament_index may be absent or not know the package
        pass
    raise ConfigError("cannot find the config directory; set TACTILE_CONFIG_DIR")
