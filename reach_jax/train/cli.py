"""The command line `python -m reach_jax.train`: flags to a Config (`config.overlay`), then `train.run`.

It parses its arguments, sets up the backend (devices, a multi-process run) and calls the library.
Every user error prints one line, "prog: error: message", and exits 2 with nothing written; so does a trainer on a
run directory that another live process trains (`store.run_lock`).
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import sys
import zlib
from pathlib import Path
from typing import NamedTuple

import jax
import numpy as np

from reach_jax import train
from reach_jax.config import (
    CONDITIONS,
    Config,
    hyper,
    to_dict,
    to_json,
    tuplify,
)
from reach_jax.config.overlay import PAPER_HYPER, build_config, checked_config, folded, same_learners, with_settings
from reach_jax.config.schema import DEFAULT_SPEED, MAX_HIDDEN_PAD, Speed
from reach_jax.engine import distribute
from reach_jax.errors import (
    EXIT_INTERRUPTED,
    EXIT_IO,
    EXIT_NUMERICS,
    EXIT_PEER,
    EXIT_USAGE,
    Parser,
    UsageError,
    error_line,
    non_negative_int,
    positive_int,
    whole_number,
)
from reach_jax.store import run_dir as run_dir_io
from reach_jax.store import run_lock
from reach_jax.store.checkpoint import CheckpointError
from reach_jax.train import interrupt


def _hidden_pad(text: str) -> int:
    return whole_number(text, 1, MAX_HIDDEN_PAD)


def _conditions(text: str) -> tuple[str, ...]:
    return tuple(n for n in text.replace(",", " ").split() if n)


def _values(h: hyper.Hyperparameter, text: str) -> tuple[float, ...]:
    """Comma-separated values of hyperparameter h, each read and range-checked by the table."""
    try:
        values = tuple(h.parse(v) for v in text.split(",") if v.strip())
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    if not values:
        raise argparse.ArgumentTypeError(f"{h.name}={text!r}: no value")
    return values


def _sweep(text: str) -> tuple[str, tuple[float, ...]]:
    """NAME=V[,V...] as (name, values), the name looked up in the hyperparameter table."""
    name, sep, raw = text.partition("=")
    if not sep:
        raise argparse.ArgumentTypeError(f"{text!r} is not NAME=V[,V...]")
    try:
        h = hyper.lookup(name.strip())
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return h.name, _values(h, raw)


class _ListHyper(argparse.Action):
    """--list-hyper: print the hyperparameter table and exit 0, as --help does."""

    def __init__(self, option_strings, dest, **kwargs):
        super().__init__(option_strings, dest, nargs=0, default=argparse.SUPPRESS, **kwargs)

    def __call__(self, parser, namespace, values, option_string=None):
        sys.stdout.write(hyper.table_text())
        parser.exit()


def _setting(text: str) -> tuple[str, str, object]:
    """SECTION.FIELD=JSON as (section, field, value); whether the field exists and the value fits is from_dict's."""
    name, sep, raw = text.partition("=")
    section, dot, field = name.strip().partition(".")
    if not sep or not dot or not section or not field:
        raise argparse.ArgumentTypeError(f"{text!r} is not SECTION.FIELD=JSON")
    try:
        return section, field, tuplify(json.loads(raw))
    except json.JSONDecodeError:
        raise argparse.ArgumentTypeError(f"{raw!r} is not a JSON value") from None


def build_train_parser() -> argparse.ArgumentParser:
    """The command-line interface of `python -m reach_jax.train`: the core flags, then the infrastructure ones."""
    p = Parser(prog="python -m reach_jax.train", description=train.__doc__.splitlines()[0], add_help=False)
    core = p.add_argument_group("core")
    core.add_argument("-h", "--help", action="help", help="show this help and exit")
    core.add_argument("--config", type=Path, metavar="FILE", help="start from this config (JSON, as in config.json)")
    core.add_argument("--trials", type=positive_int, help="trials per learner (2e6 in the paper)")
    core.add_argument("--seeds", type=positive_int, help="networks per condition (2 in the paper)")
    core.add_argument(
        "--conditions",
        type=_conditions,
        help=f"comma-separated names from the conditions table (the paper's: {','.join(CONDITIONS)}; add one with "
        "--config FILE or --set conditions.NAME.FIELD=JSON)",
    )
    core.add_argument(
        "--protocol",
        dest="protocols",
        type=_conditions,
        help="comma-separated protocols from the protocols table (shipped: adaptation, adaptation_control; add "
        "one with --config FILE or --set protocols.NAME=JSON); without --conditions only these learners run, and "
        "--trials defaults to the protocol's length",
    )
    core.add_argument("--seed", type=non_negative_int, help="master PRNG seed (default 0)")
    core.add_argument("--out", type=Path, help="run directory (default runs/<name>)")
    core.add_argument("--resume", type=Path, metavar="RUN_DIR", help="continue a run from its newest checkpoint")
    core.add_argument(
        "--set",
        type=_setting,
        action="append",
        default=[],
        metavar="SECTION.FIELD=JSON",
        help="set any config field, e.g. learner.critic_floor=-0.2 or conditions.curl.viscous=[[0,13],[-13,0]] "
        "(after --config, before the other flags); learner.NAME=V of a hyperparameter is --sweep NAME=V",
    )
    core.add_argument("--quiet", action="store_true", help="no progress bar")
    for name in PAPER_HYPER:
        h = hyper.BY_NAME[name]
        core.add_argument(
            f"--{name}",
            type=functools.partial(_values, h),
            metavar="V[,V...]",
            help=f"{h.help}; default {h.default:g}; one value sets it, several sweep it",
        )
    core.add_argument(
        "--sweep",
        type=_sweep,
        action="append",
        default=[],
        metavar="NAME=V[,V...]",
        help="any hyperparameter of --list-hyper, repeatable: one value sets it (learner.NAME), several sweep it "
        "(train.NAME_grid, crossed with the other grids); a switch takes true/false or 1/0",
    )
    core.add_argument("--list-hyper", action=_ListHyper, help="print the hyperparameters (name, default, range, help)")

    infra = p.add_argument_group("infrastructure", "devices, chunking and logging, multi-host")
    infra.add_argument(
        "--devices",
        type=positive_int,
        help="CPU only: host devices to shard learners over, one per core at most (default: one per core)",
    )
    infra.add_argument("--chunk-steps", type=positive_int, help="learner steps per compiled chunk")
    infra.add_argument(
        "--keep-every",
        type=non_negative_int,
        metavar="CHUNKS",
        help="also keep every CHUNKS-th checkpoint as a snapshot (default 0: only the newest two)",
    )
    infra.add_argument(
        "--trial-log-every",
        type=non_negative_int,
        metavar="N",
        help="log every N-th trial's movement (errors, outcome, time) to RUN_DIR/trials (default 0: no log)",
    )
    infra.add_argument(
        "--init-from",
        type=str,
        metavar="RUN_DIR",
        help="start each learner from the trained network of this run with its seed and first block's condition",
    )
    infra.add_argument(
        "--hidden-pad",
        type=_hidden_pad,
        help=f"pad the first hidden layer to a multiple of this inside the compiled loop (speed only, not stored; "
        f"1 = off; default {DEFAULT_SPEED.hidden_pad})",
    )
    infra.add_argument(
        "--multihost",
        nargs="?",
        const="",
        type=distribute.multihost_settings,
        metavar="KEY=VALUE,...",
        help="join a multi-process run (jax.distributed.initialize) with any of the settings coordinator=HOST:PORT "
        "(process 0's address, where it serves the others), num_processes=N, process_id=I (0 to N-1) and "
        f"init_timeout=SECONDS (to wait for every process to connect; default "
        f"{distribute.Cluster._field_defaults['init_timeout']}); the first three not given come from "
        "JAX_COORDINATOR_ADDRESS, JAX_NUM_PROCESSES and JAX_PROCESS_ID, else from the cluster (SLURM, Open MPI); "
        "process 0 writes the run directory, which --resume needs on a shared file system",
    )
    return p


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
    return validate(build_train_parser().parse_args(argv))


def validate(args: argparse.Namespace) -> Invocation:
    """Check parsed training arguments against the config and the file system, reading the checkpoint or source
    networks the run starts from (once: `train.run` takes them from the Invocation); writes nothing."""
    speed = Speed(**({} if args.hidden_pad is None else {"hidden_pad": args.hidden_pad}))
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
    parser = build_train_parser()
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
        print(f"run written to {inv.prepared.run_dir}", file=sys.stderr)
    return 0
