"""Where learners run: backend setup, the device mesh over the learner axis, and multi-process runs.

Learners never interact, so a batch splits along its leading (learner) axis over any set of devices: CPU
host devices, GPUs, TPUs, or the devices of several processes after `jax.distributed.initialize`. Nothing
here runs at import; the command lines call `setup_backend` before JAX's first computation.
"""

from __future__ import annotations

import argparse
import difflib
import os
import warnings
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax.experimental import multihost_utils
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from reach_jax.engine import xla_options
from reach_jax.errors import OneLineError, UsageError, non_negative_int, positive_int, whole_number


class Cluster(NamedTuple):
    """How this process joins a multi-process run; a None field is left to jax's cluster auto-detection."""

    coordinator: str | None  # HOST:PORT of the coordination service that process 0 starts
    num_processes: int | None  # processes in the run
    process_id: int | None  # this process, in [0, num_processes)
    init_timeout: int = 300  # [s] to wait for every process to connect


class ClusterError(OneLineError):
    """This process could not join the other processes of a multi-process run."""


class PeerLostError(OneLineError):
    """A collective across processes failed: another process of the run stopped or is unreachable."""


def first_line(exc: BaseException) -> str:
    """The first non-empty line of an exception's message (XLA's runtime errors span many)."""
    return next((line.strip() for line in str(exc).splitlines() if line.strip()), type(exc).__name__)


def available_cores() -> int:
    """CPU cores this process may run on."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


def setup_backend(devices: int | None = None, cluster: Cluster | None = None) -> None:
    """Set up JAX before its first computation: CPU compiler options, host device count, multi-process run.

    Args:
      devices: on CPU, the number of host devices to expose (one per core is the useful maximum);
        None asks for one per available core when JAX has not started yet, and otherwise keeps what it has.
        Ignored by GPU/TPU backends, whose devices are physical.
      cluster: join a multi-process run with `jax.distributed.initialize`; its None fields come from the
        cluster environment (SLURM, Open MPI, Cloud TPU). Raises ClusterError when they cannot be found.
        A process that cannot reach the others within `init_timeout` is ended by jax itself (SIGABRT).
    """
    xla_options.add_xla_flags()
    try:
        jax.config.update("jax_num_cpu_devices", available_cores() if devices is None else devices)
    except RuntimeError:  # JAX has already computed (called in-process, e.g. from a notebook): keep its devices
        if devices is not None and devices != len(jax.local_devices(backend="cpu")):
            warnings.warn(f"JAX already started; keeping its CPU devices, not {devices}", stacklevel=2)
    if cluster is not None:
        try:
            jax.distributed.initialize(
                cluster.coordinator,
                cluster.num_processes,
                cluster.process_id,
                initialization_timeout=cluster.init_timeout,
            )
        except (ValueError, TypeError, RuntimeError) as exc:
            hint = ""
            if None in cluster[:3]:
                hint = " (outside SLURM, Open MPI and Cloud TPU, give the coordinator, process count and process id)"
            raise ClusterError(f"cannot join the multi-process run: {first_line(exc)}{hint}") from None


def spread_devices(devices) -> list:
    """devices reordered so that every leading slice spreads over the processes as evenly as it can.

    The first device of each process, then the second of each, and so on; one process keeps its order.
    """
    seen: dict[int, int] = {}
    ranked = []
    for d in devices:
        seen[d.process_index] = seen.get(d.process_index, -1) + 1
        ranked.append(((seen[d.process_index], d.process_index), d))
    return [d for _, d in sorted(ranked, key=lambda pair: pair[0])]


def learner_mesh(n_learners: int, devices=None) -> Mesh:
    """1-D mesh ("learners") over the most devices that split n_learners evenly.

    Across processes the mesh holds a device of every process, or is one device (each process then runs
    the whole chunk itself): every process must own a slice to take part in the chunk and its gather.

    Args:
      n_learners: batch size.
      devices: devices to use (default: every device of every process, `jax.devices()`).
    """
    devices = spread_devices(jax.devices() if devices is None else devices)
    n_proc = len({d.process_index for d in devices})
    n = max(d for d in range(1, len(devices) + 1) if n_learners % d == 0 and (d == 1 or d >= n_proc))
    return Mesh(np.array(devices[:n]), ("learners",))


def shard_learners(tree, mesh: Mesh):
    """Place a batched pytree (learner axis first) on `mesh`, split along the learner axis.

    Works across processes: every process holds the same full host values and keeps its own slices.
    """
    sharding = NamedSharding(mesh, PartitionSpec("learners"))

    def place(a):
        host = np.asarray(a)
        return jax.make_array_from_callback(host.shape, sharding, lambda index: host[index])

    return jax.tree.map(place, tree)


def gather_processes(tree):
    """process_allgather(tree, tiled=True) that raises PeerLostError when another process is gone.

    Every process must call it at the same point of the program.
    """
    try:
        return multihost_utils.process_allgather(tree, tiled=True)
    # A broken gloo connection comes as ValueError ("UNKNOWN: Gloo AllGather failed"), others as JaxRuntimeError.
    except (ValueError, RuntimeError) as exc:
        raise PeerLostError(f"lost another process of the multi-process run: {first_line(exc)}") from None


def to_host(tree):
    """tree with every array whole on this process: arrays split across processes are all-gathered.

    Across processes it always meets the others, also when nothing is split (a chunk on one device runs
    whole on every process), so that a lost process shows as PeerLostError at the next chunk.
    """
    if jax.process_count() == 1:
        return tree
    if all(a.is_fully_addressable for a in jax.tree.leaves(tree)):
        gather_processes(np.zeros(1, np.int8))
        return tree
    return jax.tree.map(lambda a: a if a.is_fully_addressable else jnp.asarray(gather_processes(a)), tree)


def on_mesh(tree, mesh: Mesh):
    """tree unchanged if it is already split over mesh along the learner axis, else placed there."""
    want = NamedSharding(mesh, PartitionSpec("learners"))
    leaves = jax.tree.leaves(tree)
    if all(isinstance(a, jax.Array) and a.sharding.is_equivalent_to(want, a.ndim) for a in leaves):
        return tree
    return shard_learners(tree, mesh)


# Where --multihost looks for a setting that its own KEY=VALUE list does not give (jax itself reads only the first).
CLUSTER_ENV = {
    "coordinator": "JAX_COORDINATOR_ADDRESS",
    "num_processes": "JAX_NUM_PROCESSES",
    "process_id": "JAX_PROCESS_ID",
}


def coordinator(text: str) -> str:
    """An argparse type: HOST:PORT with a port in [1, 65535]."""
    host, sep, port = text.rpartition(":")
    if not sep or not host:
        raise argparse.ArgumentTypeError(f"{text!r} is not HOST:PORT")
    whole_number(port, 1, 65535)
    return text


# The settings of --multihost KEY=VALUE,... and how each value is read.
CLUSTER_SETTINGS = {
    "coordinator": coordinator,
    "num_processes": positive_int,
    "process_id": non_negative_int,
    "init_timeout": positive_int,
}


def multihost_settings(text: str) -> dict:
    """An argparse type: --multihost's KEY=VALUE,... (keys of CLUSTER_SETTINGS, "" for none), each value read."""
    found = {}
    for item in (part.strip() for part in text.split(",")):
        if not item:
            continue
        key, sep, value = item.partition("=")
        key = key.strip().replace("-", "_")
        if key not in CLUSTER_SETTINGS or not sep:
            close = difflib.get_close_matches(key, CLUSTER_SETTINGS, n=1)
            hint = f"closest: {close[0]}; " if close else ""
            raise argparse.ArgumentTypeError(f"{item!r} is not KEY=VALUE ({hint}keys: {', '.join(CLUSTER_SETTINGS)})")
        found[key] = CLUSTER_SETTINGS[key](value.strip())
    return found


def cluster_settings(args, environ=None) -> Cluster | None:
    """How to join a multi-process run: --multihost's settings, else the JAX_* variables of `environ`; None without
    --multihost.

    Raises UsageError for a malformed value or a process id out of range.

    Args:
      args: the parsed command line; args.multihost is None or the dict of `multihost_settings`.
      environ: environment to read (default os.environ).
    """
    if args.multihost is None:
        return None
    environ = os.environ if environ is None else environ
    found = {}
    for name, var in CLUSTER_ENV.items():
        value = args.multihost.get(name)
        if value is None and environ.get(var, "").strip():
            try:
                value = CLUSTER_SETTINGS[name](environ[var].strip())
            except argparse.ArgumentTypeError as exc:
                raise UsageError(f"{var}: {exc}") from None
        found[name] = value
    n, i = found["num_processes"], found["process_id"]
    if n is not None and i is not None and i >= n:
        raise UsageError(f"process id {i} is not below the number of processes {n}")
    if "init_timeout" in args.multihost:
        found["init_timeout"] = args.multihost["init_timeout"]
    return Cluster(**found)
