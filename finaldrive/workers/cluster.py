"""Whether this machine can drive a Ray cluster: Ray's rule, checked at once.

A Ray driver (the scheduler) submits through a raylet on its own machine: ``ray.init(address=...)``
with no raylet of that cluster here waits 60 s, then fails with a ConnectionError that names no
rule (issue 30). :func:`check_on_cluster` refuses such a start at once, reading the raylets'
command lines from /proc as Ray itself finds them (``ray._private.services.find_node_ids``).
Ray Client addresses (``ray://``) are refused too: the executor relies on object references'
completion callbacks, which a Ray Client does not give; run the scheduler on a node instead.

One scheduler drives a Ray cluster: Ray keeps a pool of worker processes per driver, so two drivers
that fill the same CPUs make Ray kill one's idle workers to start the other's (13 worker restarts
in 3.4 min, two DEs 3-3.5x slower: issue 30). A scheduler that finds the cluster taken
(:class:`ClusterTaken`, ``workers/ray_executor.py``) waits as a standby and takes over when the
first one stops or dies.
"""

from __future__ import annotations

from pathlib import Path

_PROC = Path("/proc")


class NotOnCluster(RuntimeError):
    """This machine runs no node of the Ray cluster to join (the message says what to do)."""


class ClusterTaken(RuntimeError):
    """Another finaldrive scheduler drives this Ray cluster (the message names it)."""


def local_gcs_addresses() -> set[str] | None:
    """The GCS address (``--gcs-address``) of every raylet on this machine; None where /proc
    cannot be read (not Linux), so nothing is known."""
    if not _PROC.is_dir():
        return None
    found: set[str] = set()
    for entry in _PROC.iterdir():
        if not entry.name.isdigit():
            continue
        try:
            args = (entry / "cmdline").read_bytes().split(b"\0")
        except OSError:   # gone, or not ours to read
            continue
        if args[0].rsplit(b"/", 1)[-1] != b"raylet":
            continue
        for arg in args:
            if arg.startswith(b"--gcs-address="):
                found.add(arg.split(b"=", 1)[1].decode(errors="replace"))
    return found


def check_on_cluster(address: str) -> None:
    """Raise :class:`NotOnCluster` unless a raylet on this machine belongs to the cluster at
    ``address`` (host:port; matched by port, as a node may name the head by another of its
    addresses). ``auto`` and ``local`` are Ray's to resolve."""
    rule = ("the scheduler submits simulations through the Ray node of its own machine, so it must run "
            "on the cluster's head or on a node that joined it")
    if address.startswith("ray://"):
        raise NotOnCluster(f"RAY_ADDRESS={address} is a Ray Client address, which finaldrive does not use: "
                           f"{rule}; give it the cluster's address host:port (GCS port, 6379 by default)")
    if address in ("auto", "local"):
        return
    found = local_gcs_addresses()
    if found is None:
        return
    port = address.rpartition(":")[2]
    if any(gcs.rpartition(":")[2] == port for gcs in found):
        return
    here = f"this machine runs Ray nodes of other clusters only ({', '.join(sorted(found))})" if found else \
        "no Ray node runs on this machine"
    raise NotOnCluster(f"cannot join the Ray cluster at {address}: {here}; {rule} "
                       f"(`ray start --address={address}` here first)")
