"""The command line `python -m reach_jax.train`: flags to a Config (`config.overlay`), then `train.run`.

It parses its arguments, sets up the backend (devices, a multi-process run) and calls the library.
Every user error prints one line, "prog: error: message", and exits 2 with nothing written; so does a trainer on a
run directory that another live process trains (`store.run_lock`).
"""

from __future__ import annotations

import argparse
import os
import shlex
import sys
import zlib
from pathlib import Path
from typing import NamedTuple

import jax
import numpy as np

from reach_jax import train
from reach_jax.config import (
    Config,
    to_dict,
    to_json,
    tuplify,
)
from reach_jax.config.overlay import build_config, checked_config, folded, same_learners, with_settings
from reach_jax.config.schema import Speed
from reach_jax.engine import distribute
from reach_jax.errors import (
    EXIT_INTERRUPTED,
    EXIT_IO,
    EXIT_NUMERICS,
    EXIT_PEER,
    EXIT_USAGE,
    UsageError,
    error_line,
)
from reach_jax.store import run_dir as run_dir_io
from reach_jax.store import run_lock
from reach_jax.store.checkpoint import CheckpointError
from reach_jax.train import arguments, health, interrupt


class Invocation(NamedTuple):
    """A validated training command line."""

    prepared: train.Prepared  # the checked run (config: the stored one when resuming) and what it starts from
    quiet: bool  # no progress bar

    @property
    def cfg(self) -> Config:
        """The run's config."""
        return self.prepared.cfg


def _first_existing(path: Path) -> Path:
    for candidate in (path, *path.parents):
        if candidate.exists():
            return candidate
    return Path(".")


def parse(argv=None) -> Invocation:
    """Validate a training command line without writing anything; raises UsageError or CheckpointError."""
    return validate(arguments.build_train_parser().parse_args(argv))


def validate(args: argparse.Namespace) -> Invocation:
    """Check parsed training arguments against the config and the file system, reading the checkpoint or source
    networks the run starts from (once: `train.run` takes them from the Invocation); writes nothing."""
    speed = Speed(**({} if args.hidden_pad is None else {"hidden_pad": args.hidden_pad}), engine=args.engine)
    if args.resume is not None:
        for flag in ("out", "config"):
            if getattr(args, flag) is not None:
                raise UsageError(f"--{flag} cannot be combined with --resume (the run's config.json holds it)")
        run_lock.check_free(args.resume)  # before reading: a live writer prunes checkpoints under a reader
        cfg = run_dir_io.read_config(args.resume)
        try:
            asked = checked_config(with_settings(to_dict(cfg), args))
        except (TypeError, ValueError) as exc:
            raise UsageError(str(exc)) from None
        # A one-value grid and the learner's default are the same learners: either spelling resumes either.
        diff = same_learners(cfg, asked)
        if diff:
            stored, wanted = (_field(folded(c), diff) for c in (cfg, asked))
            raise CheckpointError(f"{args.resume / run_dir_io.CONFIG_FILE}: field {diff} is {stored!r}, not {wanted!r}")
        return Invocation(train.prepare(cfg, args.resume, resume=True, speed=speed), args.quiet)
    cfg = build_config(args)
    run_dir = args.out if args.out is not None else train.default_run_dir(cfg.train)
    existing = _first_existing(run_dir)
    if not existing.is_dir():
        raise UsageError(f"--out {run_dir}: {existing} is a file, not a directory")
    run_lock.check_free(run_dir)
    if run_dir_io.holds_run(run_dir):
        raise UsageError(f"--out {run_dir} already holds a run; use --resume {run_dir}")
    try:
        return Invocation(train.prepare(cfg, run_dir, speed=speed), args.quiet)
    except ValueError as exc:  # train.init_from lacks a network
        raise UsageError(str(exc)) from None


def _field(cfg: Config, dotted: str):
    value = to_dict(cfg)
    for part in dotted.split("."):
        value = value[part]
    return tuplify(value)


def _disagreement(inv: Invocation | None) -> UsageError | None:
    """Why a multi-process run must stop before process 0 writes: a process refused its command line (inv None
    there), or the processes were given different configs. Every process calls it after checking the run directory.
    """
    mine = -1 if inv is None else zlib.crc32(f"{inv.prepared.resume} {to_json(inv.cfg)}".encode()) & 0x7FFFFFFF
    tokens = distribute.gather_processes(np.array([mine], np.int32))
    if (tokens == -1).any():
        return UsageError(f"process {int(np.argmax(tokens == -1))} of the multi-process run refused its command line")
    if (tokens != mine).any():
        return UsageError("the processes of the multi-process run were given different configs")
    return None


def main(argv=None) -> int:
    """`python -m reach_jax.train`; returns the exit status."""
    parser = arguments.build_train_parser()
    try:
        args = parser.parse_args(argv)
        # Device count and multi-process run must be fixed before JAX's first computation.
        distribute.setup_backend(args.devices, distribute.cluster_settings(args))
    except (UsageError, distribute.ClusterError) as exc:
        sys.stderr.write(error_line(parser.prog, str(exc)))
        return EXIT_USAGE
    status = _validate_and_train(args, parser.prog)
    if status and jax.distributed.is_initialized():
        # The other processes may never reach jax's shutdown barrier at exit (one of them is gone, or stopped
        # elsewhere); waiting there would block for its timeout and then abort. Leave at once instead.
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(status)
    return status


def _validate_and_train(args: argparse.Namespace, prog: str) -> int:
    """Validate, then train; returns the exit status, after printing the one-line error of a failure."""
    try:
        inv, refused = validate(args), None
    except (UsageError, CheckpointError, run_lock.RunLockedError) as exc:
        inv, refused = None, exc
    try:
        if jax.distributed.is_initialized():
            stop = _disagreement(None if refused else inv)  # a collective: a process that refused joins it too
            refused = refused or stop
        if refused is not None:
            sys.stderr.write(error_line(prog, str(refused)))
            return EXIT_USAGE
        train.run(inv.prepared, progress=not inv.quiet)
    except run_lock.RunLockedError as exc:  # another writer took the lock after this one validated
        sys.stderr.write(error_line(prog, str(exc)))
        return EXIT_USAGE
    except interrupt.Interrupted as exc:
        if jax.process_index() == 0:
            print(f"{prog}: {exc}, its checkpoint written; resume with: {exc.resume_command()}", file=sys.stderr)
        return EXIT_INTERRUPTED
    except train.NumericsError as exc:
        sys.stderr.write(error_line(prog, str(exc)))
        return EXIT_NUMERICS
    except distribute.PeerLostError as exc:
        sys.stderr.write(error_line(prog, str(exc)))
        return EXIT_PEER
    except OSError as exc:
        sys.stderr.write(error_line(prog, f"write failed, last good checkpoint kept: {exc}"))
        return EXIT_IO
    if jax.process_index() == 0:
        trouble = health.of_run(inv.prepared.run_dir).summary() or ["no learner collapsed or fell back"]
        for line in trouble:
            print(f"{prog}: {line}", file=sys.stderr)
        print(f"run written to {inv.prepared.run_dir}", file=sys.stderr)
        print(f"evaluate it: python -m reach_jax.evaluate {shlex.quote(str(inv.prepared.run_dir))}", file=sys.stderr)
    return 0
