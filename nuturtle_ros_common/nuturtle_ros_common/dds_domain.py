"""One run, one DDS world: the rclpy context of a demo or replay run, private unless the user asks to share.

A run puts every node in one rclpy Context, which rmw_fastrtps maps to one DDS participant; its nodes find
each other inside that participant. The choice (``--domain-id``, docs/demo.md):

- ``"private"``: nothing outside the run hears it or is heard by it, two ways at once:

  1. automatic discovery OFF for the run's participant. rcl reads ``ROS_AUTOMATIC_DISCOVERY_RANGE`` only
     in ``rclpy.init``, so it is set for that call alone and restored (``ROS_LOCALHOST_ONLY``, which would
     override it, is lifted for the call too): nothing changes in the environment the rest of the process
     or its children see. rmw_fastrtps then allows the participant no remote participant at all, in any
     domain, whatever the others' discovery range (measured in docs/demo.md).
  2. a domain id of its own, for middlewares whose OFF may be weaker (each implements it its own way):
     the first of ``PRIVATE_DOMAIN_IDS`` (100 down to 1; not the shell's ``ROS_DOMAIN_ID``) on which no
     process of this host has a UDP port bound in the domain's block of the RTPS port mapping
     (``7400 + 250 d`` to ``7400 + 250 d + 249``, read from /proc/net/udp and udp6 on Linux) and whose
     advisory lock (``flock`` of ``<temp dir>/nuturtle-dds-domains-<uid>/<d>.lock``) no other run holds.
     The lock is held until the context shuts down; the kernel drops it when the process dies, even by
     kill -9, so no run ever leaks a domain.

- ``"env"``: the shell's ``ROS_DOMAIN_ID`` (0 if unset) and discovery settings, as every ROS 2 program: the
  user's other shells (``ros2 topic echo``, RViz) see the run, and so does anything else there.
- an integer ``d`` in 0-232: domain ``d`` with the shell's discovery settings (``ROS_DOMAIN_ID=d`` in the
  watching shell).

Light on purpose (rclpy is imported only to build the context), so the command lines parse quickly.
"""

from __future__ import annotations

import argparse
import fcntl
import os
import tempfile
import threading
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Any

from turtlelib.util.validation import integer

if TYPE_CHECKING:
    from rclpy.context import Context

PRIVATE = "private"
ENVIRONMENT = "env"
# An int domain id, PRIVATE or ENVIRONMENT
DomainChoice = int | str
# The largest domain id whose RTPS ports (7400 + 250 d + ...) fit below 65536
MAX_DOMAIN_ID = 232
# The blocks of domains 1-100 (ports 7650-32649) lie below Linux's ephemeral ports (32768-60999), which
# any socket may get; 0 is everyone's default
PRIVATE_DOMAIN_IDS = tuple(range(100, 0, -1))
# The RTPS well-known port mapping: port base PB and domain gain DG, the block of one domain
PORT_BASE = 7400
DOMAIN_GAIN = 250
# The environment rcl reads for discovery, set for the duration of rclpy.init of a private context only
DISCOVERY_OFF = {"ROS_AUTOMATIC_DISCOVERY_RANGE": "OFF", "ROS_LOCALHOST_ONLY": None}
_environment_lock = threading.Lock()


def domain_choice(name: str, value: object) -> DomainChoice:
    """``value`` as a choice (module docstring): ``"private"``, ``"env"`` or a domain id 0-232 (an int or
    its digits); ValueError for anything else."""
    if value in (PRIVATE, ENVIRONMENT):
        return str(value)
    if isinstance(value, str) and value.strip().isdigit():
        value = int(value)
    if isinstance(value, bool) or not isinstance(value, int):
        raise ValueError(
            f"{name} must be {PRIVATE}, {ENVIRONMENT} or an integer 0-{MAX_DOMAIN_ID}, got {value!r}"
        )
    return integer(name, value, 0, MAX_DOMAIN_ID)


def _parse_choice(text: str) -> DomainChoice:
    try:
        return domain_choice("the domain id", text)
    except ValueError as error:
        raise argparse.ArgumentTypeError(str(error)) from None


def add_domain_argument(parser: argparse.ArgumentParser, default_text: str | None = None) -> None:
    """``--domain-id {private,env,0-232}``, parsed by :func:`domain_choice`: ``private`` when absent, or,
    with ``default_text`` (the help's words for a default the caller decides), no attribute at all
    (``getattr(args, "domain_id", None)``)."""
    default: Any = PRIVATE if default_text is None else argparse.SUPPRESS
    tail = "" if default_text is None else f" (default: {default_text})"
    parser.add_argument("--domain-id", type=_parse_choice, default=default, metavar="{private,env,0-232}",
                        help="DDS world of the run: private (a free domain of its own with discovery off: "
                        "no other ROS program hears it or is heard), env (the shell's ROS_DOMAIN_ID and "
                        "discovery settings, so `ros2 topic echo` in another shell sees it) or a domain id "
                        f"(that domain, with the shell's discovery settings){tail}")  # fmt: skip


def domain_ports(domain_id: int) -> range:
    """The UDP ports of domain ``domain_id``'s block in the RTPS port mapping (every participant of the
    domain binds some of them: multicast discovery at offset 0, unicast from 10 up)."""
    start = PORT_BASE + DOMAIN_GAIN * domain_id
    return range(start, start + DOMAIN_GAIN)


def bound_udp_ports(tables: Sequence[Path] = (Path("/proc/net/udp"), Path("/proc/net/udp6"))) -> set[int]:
    """The local ports of every UDP socket of this host's network namespace (Linux's /proc tables; an empty
    set where they cannot be read)."""
    ports: set[int] = set()
    for table in tables:
        try:
            lines = table.read_text(encoding="ascii").splitlines()[1:]
        except OSError:
            continue
        for line in lines:
            # "  sl  local_address rem_address ...": local_address is HEXADDR:HEXPORT
            ports.add(int(line.split()[1].rsplit(":", 1)[1], 16))
    return ports


def lock_dir() -> Path:
    """Where the domain locks of this user live (``<temp dir>/nuturtle-dds-domains-<uid>``)."""
    return Path(tempfile.gettempdir()) / f"nuturtle-dds-domains-{os.getuid()}"


@dataclass
class DomainLease:
    """Domain ``domain_id`` held by this run through the ``flock`` of the open file ``fd`` until
    :meth:`release` (or the process's end)."""

    domain_id: int
    fd: int

    def release(self) -> None:
        if self.fd >= 0:
            os.close(self.fd)  # closing the last descriptor drops the flock
            self.fd = -1


def lease_domain(
    candidates: Sequence[int] = PRIVATE_DOMAIN_IDS, directory: Path | None = None
) -> DomainLease:
    """The first of ``candidates`` that is free (module docstring), locked for this run; the shell's
    ``ROS_DOMAIN_ID`` is skipped. OSError when none is free (like a port in use) or the lock folder cannot
    be made."""
    folder = lock_dir() if directory is None else Path(directory)
    folder.mkdir(mode=0o700, parents=True, exist_ok=True)
    shell_domain = os.environ.get("ROS_DOMAIN_ID", "").strip()
    for domain_id in candidates:
        if str(domain_id) == shell_domain:
            continue
        fd = os.open(folder / f"{domain_id}.lock", os.O_RDONLY | os.O_CREAT, 0o600)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            continue
        # locked first, probed second: two of our runs never pass the probe for the same domain at once
        if bound_udp_ports().isdisjoint(domain_ports(domain_id)):
            return DomainLease(domain_id, fd)
        os.close(fd)
    raise OSError(
        f"no free DDS domain among {min(candidates)}-{max(candidates)} (each has a DDS participant or "
        "another run's lock): choose one with --domain-id"
    )


def _set_environment(values: dict[str, str | None]) -> None:
    for key, value in values.items():
        if value is None:
            os.environ.pop(key, None)
        else:
            os.environ[key] = value


@contextmanager
def _environment(values: dict[str, str | None]) -> Iterator[None]:
    """``values`` in os.environ (None: unset) inside the block, the previous values back after it; one
    block at a time in this process."""
    with _environment_lock:
        saved = {key: os.environ.get(key) for key in values}
        try:
            _set_environment(values)
            yield
        finally:
            _set_environment(saved)


def run_context(choice: DomainChoice, **init_options: Any) -> Context:
    """A new initialised rclpy Context in the DDS world ``choice`` (module docstring); ``init_options`` go to
    ``rclpy.init`` (e.g. ``signal_handler_options``). A private context holds its domain lease until it
    shuts down (``rclpy.try_shutdown(context=...)``). OSError when no private domain is free."""
    import rclpy
    from rclpy.context import Context

    context = Context()
    if choice == ENVIRONMENT:
        rclpy.init(context=context, **init_options)
        return context
    if choice != PRIVATE:
        rclpy.init(context=context, domain_id=domain_choice("domain_id", choice), **init_options)
        return context
    lease = lease_domain()
    try:
        with _environment(DISCOVERY_OFF):
            rclpy.init(context=context, domain_id=lease.domain_id, **init_options)
    except BaseException:
        lease.release()
        raise
    # a plain callable: the context keeps it (and so the lease) alive, unlike a bound method
    context.on_shutdown(partial(DomainLease.release, lease))
    return context
