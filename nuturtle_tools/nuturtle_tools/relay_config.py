"""Where the Foxglove relay serves (docs/live.md): its config, ``HOST:PORT`` parsing and the ``--foxglove``
option of the demo and the replay. Light on purpose (no ROS import), so the command lines parse quickly."""

from __future__ import annotations

import argparse
from dataclasses import dataclass

from turtlelib.util.validation import integer, positive, store

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 8765


def parse_endpoint(text: str) -> tuple[str, int]:
    """``HOST:PORT``, ``HOST`` or ``:PORT`` (the other part from ``127.0.0.1:8765``; an IPv6 host in
    brackets: ``[::1]:8765``) as ``(host, port)``; ValueError for anything else."""
    host, sep, port_text = text.strip().rpartition(":")
    if not sep or "]" in port_text:
        host, port_text = text.strip(), ""
    host = host.removeprefix("[").removesuffix("]") or DEFAULT_HOST
    try:
        port = int(port_text) if port_text else DEFAULT_PORT
    except ValueError:
        raise ValueError(f"expected HOST:PORT, got {text!r}") from None
    config = RelayConfig(host=host, port=port)
    return config.host, config.port


@dataclass(frozen=True)
class RelayConfig:
    """The relay's server: ``host`` the address to bind (``127.0.0.1``: this machine only; any other, such
    as ``0.0.0.0``, exposes every topic to that network); ``port`` the TCP port (0-65535; 0: any free
    port); ``discovery_period`` (s, > 0) between two looks for new topics."""

    host: str = DEFAULT_HOST
    port: int = DEFAULT_PORT
    discovery_period: float = 0.5

    def __post_init__(self) -> None:
        if not self.host or any(c.isspace() for c in self.host):
            raise ValueError(f"host must be an address or host name, got {self.host!r}")
        object.__setattr__(self, "port", integer("port", self.port, 0, 65535))
        store(self, ("discovery_period",), positive)


def add_foxglove_argument(parser: argparse.ArgumentParser, pacing: str) -> None:
    """``--foxglove [HOST:PORT]`` (a string, None when absent: :func:`parse_endpoint` it); ``pacing`` names
    the option that plays at robot speed."""
    parser.add_argument("--foxglove", nargs="?", const=f"{DEFAULT_HOST}:{DEFAULT_PORT}", default=None,
                        metavar="HOST:PORT",
                        help=f"serve every topic live on a Foxglove WebSocket (default {DEFAULT_HOST}:"
                        f"{DEFAULT_PORT}, this machine only; another address such as 0.0.0.0 exposes every "
                        f"topic to that network); add {pacing} to watch at robot speed")  # fmt: skip


def check_port_free(host: str, port: int) -> None:
    """OSError (naming ``host:port``) when nothing could listen there now, e.g. another relay or demo
    serves on it: checked before a run starts. Port 0 (any free port) is always fine."""
    import socket

    if port == 0:
        return
    try:
        family, kind, proto, _, address = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)[0]
        with socket.socket(family, kind, proto) as probe:
            probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            probe.bind(address)
            probe.listen(1)
    except OSError as error:
        raise OSError(f"cannot serve Foxglove on {host}:{port}: {error.strerror or error}") from None
