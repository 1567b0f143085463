"""Hosts made of Linux network namespaces on this machine, joined by veth links to a switch.

A multi-machine robot needs a network between its machines; a bench or a
test on one machine gets one from the kernel: each *host* is a network
namespace (``ip netns``) with its loopback and one Ethernet link ``eth0``, a
veth pair whose other end is a port of a Linux bridge in one more namespace,
the *switch*.  Every address lives inside these namespaces (the host ``k``
is ``198.18.0.<k+1>/24``, the range set aside for network benchmarks, RFC
2544), every interface is made inside them (``ip -n``), and removing the
namespaces removes everything: this machine's own interfaces, addresses and
routes are never touched.  Discovery and data between the hosts can only
take these links, since they are the namespaces' only ones.

Each host gets a multicast route on its link, so DDS's simple discovery
(multicast announcements, ``ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET``) reaches
the other hosts and nothing else; the bridge floods multicast to every port.

A *link drop* takes the switch's port of a host down (the cable pulled at
the switch): the host's ``eth0`` loses its carrier and keeps its address
and routes, as a machine does when its cable is pulled, so the graph can
recover by itself when the port comes back.

:class:`VirtualHosts` is a context manager that removes its namespaces on
exit, on an exception, and (a finalizer) when the process exits without
reaching it.  Needs ``ip`` (Debian's iproute2) and CAP_NET_ADMIN / CAP_SYS_ADMIN
(root); :func:`namespaces_unavailable` says why they cannot be made here.

Written here, not taken from a library: pyroute2 would do the netlink calls,
but ``ip netns exec`` is what starts the node processes in a namespace
anyway, and a few ``ip`` commands are all the set-up there is.
"""

from __future__ import annotations

import ctypes
import ipaddress
import json
import os
import re
import shutil
import subprocess
import weakref
from collections.abc import Sequence
from dataclasses import dataclass

from tactile_descriptors_ros.errors import TactileError

__all__ = [
    "LinkCounters",
    "VirtualHosts",
    "namespaces_unavailable",
    "remove_stale_namespaces",
    "enter_namespace",
    "NamespaceError",
    "SUBNET",
]

#: Addresses of the hosts: the network-benchmark range (RFC 2544), only ever inside the namespaces.
SUBNET = ipaddress.ip_network("198.18.0.0/24")
#: The multicast range routed over each host's link (DDS discovery announcements).
MULTICAST = "224.0.0.0/4"
#: Name of every host's link inside its namespace.
LINK = "eth0"
_CLONE_NEWNET = 0x40000000
_NAME = re.compile(r"^[A-Za-z0-9_.-]{1,40}$")
_COMMAND_TIMEOUT_S = 30.0


class NamespaceError(TactileError, RuntimeError):
    """An ``ip`` command or ``setns`` failed (its output in the message)."""


def _ip(*args: str, check: bool = True) -> subprocess.CompletedProcess:
    out = subprocess.run(["ip", *args], capture_output=True, text=True, timeout=_COMMAND_TIMEOUT_S)
    if check and out.returncode != 0:
        raise NamespaceError(f"ip {' '.join(args)}: {out.stderr.strip() or out.stdout.strip()}")
    return out


def namespaces_unavailable() -> str | None:
    """Why network namespaces cannot be made here (``None`` when they can): no ``ip``, not privileged, ...

    Tries it: makes a namespace with one veth pair inside and removes it.
    """
    if shutil.which("ip") is None:
        return "the ip command (iproute2) is not installed"
    name = f"tactile-probe-{os.getpid()}"
    try:
        made = _ip("netns", "add", name, check=False)
        if made.returncode != 0:
            return f"cannot make a network namespace (needs CAP_SYS_ADMIN and CAP_NET_ADMIN): {made.stderr.strip()}"
        veth = _ip("-n", name, "link", "add", "probe0", "type", "veth", "peer", "name", "probe1", check=False)
        if veth.returncode != 0:
            return f"cannot make a veth pair in a network namespace: {veth.stderr.strip()}"
        return None
    except (OSError, subprocess.SubprocessError) as exc:
        return f"ip failed: {exc}"
    finally:
        _ip("netns", "del", name, check=False)


@dataclass(frozen=True)
class LinkCounters:
    """A host link's counters (the kernel's, as ``ip -s link`` shows them)."""

    rx_bytes: int
    tx_bytes: int
    rx_packets: int
    tx_packets: int
    rx_dropped: int
    tx_dropped: int

    def __sub__(self, other: LinkCounters) -> LinkCounters:
        return LinkCounters(*(a - b for a, b in zip(self.astuple(), other.astuple())))

    def astuple(self) -> tuple[int, ...]:
        return (self.rx_bytes, self.tx_bytes, self.rx_packets, self.tx_packets, self.rx_dropped, self.tx_dropped)

    def to_dict(self) -> dict[str, int]:
        return dict(zip(("rx_bytes", "tx_bytes", "rx_packets", "tx_packets", "rx_dropped", "tx_dropped"),
                        self.astuple()))


def remove_stale_namespaces() -> list[str]:
    """Remove the namespaces a killed bench left: ``tactile-<pid>-*`` whose process ``pid`` no longer runs.

    A bench ended by SIGKILL cannot remove its hosts; the next one does.
    Namespaces of running processes, and any other namespace, are left alone.
    """
    out = _ip("-j", "netns", "list", check=False)
    removed = []
    for entry in json.loads(out.stdout or "[]") if out.returncode == 0 else []:
        m = re.match(r"^tactile-(\d+)-", entry.get("name", ""))
        if m and not os.path.exists(f"/proc/{m.group(1)}"):
            _ip("netns", "del", entry["name"], check=False)
            removed.append(entry["name"])
    return removed


def _cleanup(names: list[str]) -> None:
    for name in reversed(names):
        _ip("netns", "del", name, check=False)
    names.clear()


class VirtualHosts:
    """Hosts (network namespaces) joined by veth links to a bridge: a small network on this machine.

    Parameters
    ----------
    hosts : sequence of str
        Host names (letters, digits, ``_.-``); host ``k`` gets address
        ``198.18.0.<k+1>``.
    tag : str, optional
        Part of every namespace's name (default: this process's id), so that
        concurrent runs never share one: ``tactile-<tag>-<host>``.

    Examples
    --------
    >>> with VirtualHosts(["a", "b"]) as net:                  # doctest: +SKIP
    ...     subprocess.run([*net.exec_prefix("a"), "ping", "-c1", net.address("b")])
    """

    def __init__(self, hosts: Sequence[str], *, tag: str | None = None) -> None:
        hosts = list(hosts)
        if not hosts or len(set(hosts)) != len(hosts) or not all(_NAME.match(h) for h in hosts):
            raise ValueError(f"host names must be distinct and of letters, digits, '_.-': {hosts!r}")
        if len(hosts) > SUBNET.num_addresses - 2:
            raise ValueError(f"at most {SUBNET.num_addresses - 2} hosts, got {len(hosts)}")
        self.hosts = hosts
        self.tag = tag or str(os.getpid())
        self.switch = f"tactile-{self.tag}-switch"
        self._made: list[str] = []
        self._finalizer = weakref.finalize(self, _cleanup, self._made)

    # ------------------------------------------------------------- names
    def namespace(self, host: str) -> str:
        """The namespace of ``host``."""
        self._check(host)
        return f"tactile-{self.tag}-{host}"

    def address(self, host: str) -> str:
        """The IPv4 address of ``host`` on its link."""
        self._check(host)
        return str(SUBNET.network_address + 1 + self.hosts.index(host))

    def port(self, host: str) -> str:
        """The switch's port (interface in the switch namespace) that ``host``'s link plugs into."""
        self._check(host)
        return f"p{self.hosts.index(host)}"

    def exec_prefix(self, host: str) -> list[str]:
        """The command prefix that runs a program on ``host`` (``ip netns exec <namespace>``)."""
        return ["ip", "netns", "exec", self.namespace(host)]

    def _check(self, host: str) -> None:
        if host not in self.hosts:
            raise KeyError(f"no host {host!r} (hosts: {', '.join(self.hosts)})")

    # ---------------------------------------------------------- life cycle
    def create(self) -> VirtualHosts:
        """Make the switch, the hosts and their links (removing all of it again if any step fails)."""
        if self._made:
            raise RuntimeError("the hosts exist already")
        remove_stale_namespaces()
        try:
            self._add_namespace(self.switch)
            _ip("-n", self.switch, "link", "add", "br0", "type", "bridge", "mcast_snooping", "0")
            _ip("-n", self.switch, "link", "set", "br0", "up")
            for host in self.hosts:
                ns = self.namespace(host)
                self._add_namespace(ns)
                port = self.port(host)
                # both ends are made inside the namespaces: nothing ever appears in this machine's own one
                _ip("-n", self.switch, "link", "add", port, "type", "veth", "peer", "name", LINK, "netns", ns)
                _ip("-n", self.switch, "link", "set", port, "master", "br0")
                _ip("-n", self.switch, "link", "set", port, "up")
                _ip("-n", ns, "link", "set", "lo", "up")
                _ip("-n", ns, "addr", "add", f"{self.address(host)}/{SUBNET.prefixlen}", "dev", LINK)
                _ip("-n", ns, "link", "set", LINK, "up")
                _ip("-n", ns, "route", "add", MULTICAST, "dev", LINK)
        except BaseException:
            self.remove()
            raise
        return self

    def _add_namespace(self, name: str) -> None:
        _ip("netns", "add", name)
        self._made.append(name)

    def remove(self) -> None:
        """Remove every namespace made (their links and addresses go with them)."""
        _cleanup(self._made)

    @property
    def namespaces(self) -> list[str]:
        """The namespaces that exist now (made and not yet removed)."""
        return list(self._made)

    def __enter__(self) -> VirtualHosts:
        return self.create()

    def __exit__(self, *exc: object) -> None:
        self.remove()

    # ---------------------------------------------------------- the links
    def set_link(self, host: str, up: bool) -> None:
        """Plug ``host``'s cable in (``up``) or pull it out at the switch (its port down)."""
        _ip("-n", self.switch, "link", "set", self.port(host), "up" if up else "down")

    def has_carrier(self, host: str) -> bool:
        """Whether ``host``'s link sees its switch port (``LOWER_UP``): the kernel reports a carrier change a
        moment after the port changes."""
        out = _ip("-n", self.namespace(host), "-j", "link", "show", LINK)
        return "LOWER_UP" in json.loads(out.stdout)[0].get("flags", [])

    def counters(self, host: str) -> LinkCounters:
        """The counters of ``host``'s link, read inside its namespace."""
        out = _ip("-n", self.namespace(host), "-s", "-j", "link", "show", LINK)
        st = json.loads(out.stdout)[0]["stats64"]
        return LinkCounters(int(st["rx"]["bytes"]), int(st["tx"]["bytes"]), int(st["rx"]["packets"]),
                            int(st["tx"]["packets"]), int(st["rx"]["dropped"]), int(st["tx"]["dropped"]))


def enter_namespace(path_or_name: str) -> None:
    """Move the calling *thread* into a network namespace (``ip netns`` name or a ``/proc/.../ns/net`` path).

    Sockets the thread opens afterwards, and threads it starts (a DDS
    participant's), live in that namespace; other threads of the process
    stay where they are.  Used to run an rclpy context on one of the
    :class:`VirtualHosts` from inside a bench process.
    """
    path = path_or_name if "/" in path_or_name else f"/var/run/netns/{path_or_name}"
    libc = ctypes.CDLL(None, use_errno=True)
    fd = os.open(path, os.O_RDONLY | os.O_CLOEXEC)
    try:
        if libc.setns(fd, _CLONE_NEWNET) != 0:
            err = ctypes.get_errno()
            raise NamespaceError(f"setns({path}): {os.strerror(err)}")
    finally:
        os.close(fd)
