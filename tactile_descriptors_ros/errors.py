"""Every exception the package raises, in one place.

All derive from :class:`TactileError`, so a caller can catch the package's
errors without catching programming errors.  Where an error is about bad
input it also derives from :class:`ValueError`, and errors about devices from
:class:`OSError`, so generic handlers keep working.
"""

from __future__ import annotations

__all__ = [
    "TactileError",
    "ConfigError",
    "SchemaError",
    "SignalError",
    "CodecError",
    "ParityError",
    "ErrorWordError",
    "WordFormatError",
    "FrameError",
    "ChecksumError",
    "TransportError",
    "TransportUnavailableError",
    "ModelError",
    "SceneError",
    "DataFormatError",
    "BagError",
    "NodeExitedError",
]


class TactileError(Exception):
    """Base class of every error raised by tactile_descriptors_ros."""


class ConfigError(TactileError, ValueError):
    """A robot description, scene or parameter is wrong.

    Parameters
    ----------
    message : str
        What is wrong, in words a user can act on.
    key : str, optional
        Dotted path of the offending key (``"body_parts[2].cells[0].id"``);
        it is prefixed to the message so the user sees where to look.
    source : str, optional
        File the key was read from.
    """

    def __init__(self, message: str, key: str | None = None, source: str | None = None) -> None:
        self.key = key
        self.source = source
        where = ""
        if source:
            where += f"{source}: "
        if key:
            where += f"'{key}': "
        super().__init__(where + message)


class SchemaError(ConfigError):
    """A node's parameter schema is wrong (a name given twice, an unknown type, a default outside its range).

    Keyed ``<executable>.<parameter>``; raised when the schema is built, so a
    broken schema fails every import and test of its node.
    """


class SignalError(TactileError, ValueError):
    """Signals passed to the core have incompatible shapes, types or lengths."""


class CodecError(TactileError, ValueError):
    """Bytes from a sensor bus could not be decoded."""


class ParityError(CodecError):
    """A BioTac reply byte failed its odd-parity check."""


class ErrorWordError(CodecError):
    """A BioTac replied with one of its error words (0xA545, 0xA53F, 0xA52D, 0xA558)."""

    def __init__(self, message: str, word: int) -> None:
        self.word = word
        super().__init__(message)


class WordFormatError(CodecError):
    """A BioTac reply word passed parity but its two must-be-zero bits (low byte bits 2..1) are set."""


class FrameError(CodecError):
    """A serial or CAN frame is truncated, too long, or malformed."""


class ChecksumError(FrameError):
    """A frame's checksum (CRC) does not match its contents."""


class TransportError(TactileError, OSError):
    """A transport (SPI adapter, serial port, CAN bus) failed."""


class TransportUnavailableError(TransportError):
    """A transport's library or device is not available on this machine."""


class ModelError(TactileError):
    """A classifier model file is missing, corrupt or incompatible."""


class SceneError(ConfigError):
    """A simulation scene is wrong."""


class DataFormatError(TactileError, ValueError):
    """A recording (CSV, bag) does not have the expected layout."""


class BagError(TactileError):
    """A bag could not be written, read or replayed."""


class NodeExitedError(TactileError):
    """A node of a launched graph ended on its own: the launch ends too, naming the node and its exit code.

    Parameters
    ----------
    node : str
    code : int
    """

    def __init__(self, node: str, code: int) -> None:
        self.node = node
        self.code = code
        super().__init__(f"node {node} exited with code {code}: stopping the launch (a graph with a node "
                         "missing recognises nothing)")
