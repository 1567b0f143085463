"""Transports: one interface (:class:`~.base.Transport`), backends chosen by name.

===========  ======================================  ====================================
name         class                                   needs
===========  ======================================  ====================================
cheetah      :class:`~.cheetah.CheetahTransport`     Total Phase ``cheetah_py`` (not shipped)
serial       :class:`~.serial_port.SerialTransport`  pyserial
can          :class:`~.can_bus.CanTransport`         python-can
loopback     :class:`~.loopback.LoopbackTransport`   nothing
simulated    :class:`~.simulated.SimulatedTransport` a source object
===========  ======================================  ====================================

Backends are imported only when created, so a missing optional library only
matters for the backend that needs it::

    from tactile_descriptors_ros.transports import create_transport
    with create_transport("serial", port="loop://") as t:
        t.write(b"...")
"""

from __future__ import annotations

import importlib
import inspect
from typing import Any

from ..errors import ConfigError
from .base import ByteTransport, MessageTransport, SpiSegment, SpiTransport, Transport

__all__ = ["Transport", "ByteTransport", "SpiTransport", "SpiSegment", "MessageTransport",
           "TRANSPORTS", "register_transport", "transport_class", "create_transport"]

#: Backend name -> ``"module:Class"`` (module relative to this package or absolute).
TRANSPORTS: dict[str, str] = {
    "cheetah": ".cheetah:CheetahTransport",
    "serial": ".serial_port:SerialTransport",
    "can": ".can_bus:CanTransport",
    "loopback": ".loopback:LoopbackTransport",
    "simulated": ".simulated:SimulatedTransport",
}


def register_transport(name: str, target: str) -> None:
    """Add a backend: ``target`` is ``"package.module:Class"``."""
    if ":" not in target:
        raise ConfigError(f"transport target must be 'module:Class', got {target!r}")
    TRANSPORTS[str(name)] = target


def transport_class(name: str) -> type[Transport]:
    """The class of a backend (imports its module).

    Raises
    ------
    ConfigError
        Unknown backend name.
    """
    target = TRANSPORTS.get(str(name))
    if target is None:
        raise ConfigError(f"unknown transport {name!r}; known: {', '.join(sorted(TRANSPORTS))}",
                          key="transport")
    module_name, cls_name = target.split(":")
    module = importlib.import_module(module_name, package=__name__ if module_name.startswith(".") else None)
    return getattr(module, cls_name)


def create_transport(name: str, **params: Any) -> Transport:
    """Create (not open) a transport by name with its parameters.

    Raises
    ------
    ConfigError
        Unknown backend or parameters it does not take.
    """
    cls = transport_class(name)
    try:
        inspect.signature(cls).bind(**params)
    except TypeError as exc:
        raise ConfigError(f"bad parameters for transport {name!r}: {exc}", key="transport") from None
    try:
        return cls(**params)
    except ConfigError:
        raise
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"bad parameters for transport {name!r}: {exc}", key="transport") from None
