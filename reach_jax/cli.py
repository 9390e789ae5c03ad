"""The command lines: `python -m reach_jax.train` and `python -m reach_jax.evaluate`.

Each parses its arguments into a Config (or a run directory), sets up the backend and calls the library
(`train.run`, `evaluate.evaluate`). Every user error prints one line, "prog: error: message", and exits 2
with nothing written.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import zlib
from pathlib import Path
from typing import NamedTuple

import jax
import numpy as np

from reach_jax import compat, distribute, evaluate, hyper, train
from reach_jax import run_dir as run_dir_io
from reach_jax.checkpoint import CheckpointError
from reach_jax.config import (
    CONDITIONS,
    CONFIG_VERSION,
    Config,
    first_difference,
    from_dict,
    protocol_trials,
    to_dict,
    to_json,
    tuplify,
    with_defaults,
)
from reach_jax.errors import OneLineError, printable
from reach_jax.evaluate import animation
from reach_jax.speed import DEFAULT_SPEED, MAX_HIDDEN_PAD, Speed

EXIT_USAGE = 2  # bad arguments, config or checkpoint; nothing written
EXIT_NUMERICS = 3  # a learner went non-finite; the last good checkpoint is kept
EXIT_IO = 4  # a write failed; the last good checkpoint (or the run) is kept
EXIT_PEER = 5  # another process of a multi-process run stopped; the last good checkpoint is kept

# Where --multihost looks for a setting that its flag does not give (jax itself reads only the first).
CLUSTER_ENV = {
    "coordinator": "JAX_COORDINATOR_ADDRESS",
    "num_processes": "JAX_NUM_PROCESSES",
    "process_id": "JAX_PROCESS_ID",
}

# Training flag -> the TrainConfig field it sets; a hyperparameter's flag sets its sweep grid.
TRAIN_FLAGS = {
    **{name: name for name in ("trials", "seeds", "conditions", "seed", "chunk_steps", "keep_every")},
    **{name: name for name in ("protocols", "init_from", "trial_log_every")},
    **{h.name: h.grid for h in hyper.TABLE},
}


class UsageError(OneLineError):
    """Bad command-line input; the message is one line."""


def error_line(prog: str, message: str) -> str:
    """The one line a command prints for a user error: "prog: error: message", control characters escaped."""
    return f"{prog}: error: {printable(message)}\n"


class Parser(argparse.ArgumentParser):
    """An ArgumentParser that raises UsageError instead of printing and exiting."""

    def error(self, message):
        raise UsageError(message)


def _whole_number(text: str, minimum: int, maximum: int = 2**31 - 1) -> int:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not math.isfinite(value) or value < minimum or value != int(value) or value > maximum:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number in [{minimum}, {maximum}]")
    return int(value)


def _positive_int(text: str) -> int:
    return _whole_number(text, 1)


def _hidden_pad(text: str) -> int:
    return _whole_number(text, 1, MAX_HIDDEN_PAD)


def _non_negative_int(text: str) -> int:
    return _whole_number(text, 0)


def _coordinator(text: str) -> str:
    host, sep, port = text.rpartition(":")
    if not sep or not host:
        raise argparse.ArgumentTypeError(f"{text!r} is not HOST:PORT")
    _whole_number(port, 1, 65535)
    return text


def _conditions(text: str) -> tuple[str, ...]:
    return tuple(n for n in text.replace(",", " ").split() if n)


def _numbers(text: str) -> tuple[float, ...]:
    try:
        values = tuple(float(v) for v in text.split(",") if v.strip())
    except ValueError:
        values = ()
    if not values:
        raise argparse.ArgumentTypeError(f"{text!r} is not a comma-separated list of numbers")
    return values


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
    """The command-line interface of `python -m reach_jax.train`."""
    p = Parser(prog="python -m reach_jax.train", description=train.__doc__.splitlines()[0])
    p.add_argument("--config", type=Path, metavar="FILE", help="start from this config (JSON, as in config.json)")
    p.add_argument("--trials", type=_positive_int, help="trials per learner (2e6 in the paper)")
    p.add_argument("--seeds", type=_positive_int, help="networks per condition (2 in the paper)")
    p.add_argument(
        "--conditions",
        type=_conditions,
        help=f"comma-separated names from the conditions table (the paper's: {','.join(CONDITIONS)}; add one with "
        "--config FILE or --set conditions.NAME.FIELD=JSON)",
    )
    p.add_argument(
        "--protocol",
        dest="protocols",
        type=_conditions,
        help="comma-separated protocols from the protocols table (shipped: adaptation, adaptation_control; add "
        "one with --config FILE or --set protocols.NAME=JSON); without --conditions only these learners run, and "
        "--trials defaults to the protocol's length",
    )
    p.add_argument(
        "--init-from",
        type=str,
        metavar="RUN_DIR",
        help="start each learner from the trained network of this run with its seed and first block's condition",
    )
    p.add_argument(
        "--trial-log-every",
        type=_non_negative_int,
        metavar="N",
        help="log every N-th trial's movement (errors, outcome, time) to RUN_DIR/trials (default 0: no log)",
    )
    p.add_argument("--seed", type=_non_negative_int, help="master PRNG seed (default 0)")
    p.add_argument("--chunk-steps", type=_positive_int, help="learner steps per compiled chunk")
    for h in hyper.TABLE:
        p.add_argument(h.flag, type=_numbers, metavar="X[,X...]", help=f"{h.help}; a comma-separated list sweeps it")
    p.add_argument(
        "--keep-every",
        type=_non_negative_int,
        metavar="CHUNKS",
        help="also keep every CHUNKS-th checkpoint as a snapshot (default 0: only the newest two)",
    )
    p.add_argument(
        "--set",
        type=_setting,
        action="append",
        default=[],
        metavar="SECTION.FIELD=JSON",
        help="set any config field, e.g. learner.lr=0.5 or conditions.curl.viscous=[[0,13],[-13,0]] "
        "(after --config, before the flags above)",
    )
    p.add_argument("--out", type=Path, help="run directory (default runs/<name>)")
    p.add_argument("--resume", type=Path, metavar="RUN_DIR", help="continue a run from its newest checkpoint")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument(
        "--hidden-pad",
        type=_hidden_pad,
        help=f"pad the first hidden layer to a multiple of this inside the compiled loop (speed only, not stored; "
        f"1 = off; default {DEFAULT_SPEED.hidden_pad})",
    )
    p.add_argument(
        "--devices",
        type=_positive_int,
        help="CPU only: host devices to shard learners over, one per core at most (default: one per core)",
    )
    p.add_argument(
        "--multihost",
        action="store_true",
        help="join a multi-process run (jax.distributed.initialize); the three settings below come from their "
        "flags, else from JAX_COORDINATOR_ADDRESS, JAX_NUM_PROCESSES and JAX_PROCESS_ID, else from the cluster "
        "(SLURM, Open MPI); process 0 writes the run directory, which --resume needs on a shared file system",
    )
    p.add_argument(
        "--coordinator",
        type=_coordinator,
        metavar="HOST:PORT",
        help="with --multihost: address of process 0, where it serves the other processes",
    )
    p.add_argument("--num-processes", type=_positive_int, metavar="N", help="with --multihost: processes in the run")
    p.add_argument("--process-id", type=_non_negative_int, metavar="I", help="with --multihost: this process, 0 to N-1")
    p.add_argument(
        "--init-timeout",
        type=_positive_int,
        metavar="SECONDS",
        help="with --multihost: how long to wait for every process to connect "
        f"(default {distribute.Cluster._field_defaults['init_timeout']})",
    )
    return p


def cluster_settings(args, environ=None) -> distribute.Cluster | None:
    """How to join a multi-process run: the flags, else the JAX_* variables of `environ`; None without --multihost.

    Raises UsageError for a malformed value, a process id out of range, or a cluster flag without --multihost.

    Args:
      args: the parsed command line.
      environ: environment to read (default os.environ).
    """
    if not args.multihost:
        given = [name for name in (*CLUSTER_ENV, "init_timeout") if getattr(args, name) is not None]
        if given:
            raise UsageError(f"--{given[0].replace('_', '-')} needs --multihost")
        return None
    environ = os.environ if environ is None else environ
    parse_value = {"coordinator": _coordinator, "num_processes": _positive_int, "process_id": _non_negative_int}
    found = {}
    for name, var in CLUSTER_ENV.items():
        value = getattr(args, name)
        if value is None and environ.get(var, "").strip():
            try:
                value = parse_value[name](environ[var].strip())
            except argparse.ArgumentTypeError as exc:
                raise UsageError(f"{var}: {exc}") from None
        found[name] = value
    n, i = found["num_processes"], found["process_id"]
    if n is not None and i is not None and i >= n:
        raise UsageError(f"process id {i} is not below the number of processes {n}")
    if args.init_timeout is not None:
        found["init_timeout"] = args.init_timeout
    return distribute.Cluster(**found)


def read_config_file(path: Path) -> dict:
    """The JSON object of a --config file; raises UsageError naming the file."""
    try:
        data = json.loads(Path(path).read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise UsageError(f"--config {path}: unreadable ({exc})") from None
    if not isinstance(data, dict):
        raise UsageError(f"--config {path}: expected a JSON object")
    return data


def _checked_config(data: dict) -> Config:
    """Config of --config data with the settings applied: without a version (or of the current one) the fields
    given over the defaults, of an older version migrated as a stored config is."""
    if data.get("version", CONFIG_VERSION) == CONFIG_VERSION:
        data = with_defaults(data)
    return from_dict(data)


def _with_settings(data: dict, args) -> dict:
    """Config data with the --set values and the training flags written over it, in that order."""
    data = json.loads(json.dumps(data))  # a deep copy that the caller's dict never sees
    for section, field, value in args.set:
        if compat.retired(section, field):
            raise UsageError(f"--set {section}.{field}: no longer a config field (a speed setting: see --help)")
        part = data.setdefault(section, {})
        if section == "conditions":  # conditions.NAME.FIELD: a field of one condition, added if it is new
            name, _, field = field.partition(".")
            part = part.setdefault(name, {}) if isinstance(part, dict) else None
        if not isinstance(part, dict):
            raise UsageError(f"--set {section}.{field}: {section} is not a section")
        part[field] = value
    for flag, field in TRAIN_FLAGS.items():
        if getattr(args, flag) is not None:
            data.setdefault("train", {})[field] = getattr(args, flag)
    if args.protocols is not None:
        # A protocol run trains only the protocol's learners, for as long as the protocol lasts, unless told otherwise.
        if args.conditions is None:
            data["train"]["conditions"] = ()
        if args.trials is None and ("train", "trials") not in {(section, field) for section, field, _ in args.set}:
            try:
                lengths = {n: protocol_trials(data.get("protocols", {}), n) for n in args.protocols}
            except ValueError as exc:
                raise UsageError(str(exc)) from None
            data["train"]["trials"] = max(lengths.values())
    return data


def build_config(args) -> Config:
    """Config from --config (else the defaults), the --set values and the training flags, checked by from_dict."""
    data = read_config_file(args.config) if args.config is not None else to_dict(Config())
    try:
        return _checked_config(_with_settings(data, args))
    except (TypeError, ValueError) as exc:
        raise UsageError(str(exc)) from None


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
        cfg = run_dir_io.read_config(args.resume)
        try:
            asked = _checked_config(_with_settings(to_dict(cfg), args))
        except (TypeError, ValueError) as exc:
            raise UsageError(str(exc)) from None
        diff = first_difference(cfg, asked)
        if diff:
            stored, wanted = (_field(c, diff) for c in (cfg, asked))
            raise CheckpointError(f"{args.resume / run_dir_io.CONFIG_FILE}: field {diff} is {stored!r}, not {wanted!r}")
        return Invocation(train.prepare(cfg, args.resume, resume=True, speed=speed), args.quiet)
    cfg = build_config(args)
    run_dir = args.out if args.out is not None else train.default_run_dir(cfg.train)
    existing = _first_existing(run_dir)
    if not existing.is_dir():
        raise UsageError(f"--out {run_dir}: {existing} is a file, not a directory")
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


def train_main(argv=None) -> int:
    """`python -m reach_jax.train`; returns the exit status."""
    parser = build_train_parser()
    try:
        args = parser.parse_args(argv)
        # Device count and multi-process run must be fixed before JAX's first computation.
        distribute.setup_backend(args.devices, cluster_settings(args))
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
    except (UsageError, CheckpointError) as exc:
        inv, refused = None, exc
    try:
        if jax.distributed.is_initialized():
            stop = _disagreement(None if refused else inv)  # a collective: a process that refused joins it too
            refused = refused or stop
        if refused is not None:
            sys.stderr.write(error_line(prog, str(refused)))
            return EXIT_USAGE
        train.run(inv.prepared, progress=not inv.quiet)
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


def build_evaluate_parser() -> argparse.ArgumentParser:
    """The command-line interface of `python -m reach_jax.evaluate`."""
    p = Parser(prog="python -m reach_jax.evaluate", description=evaluate.__doc__.splitlines()[0])
    p.add_argument("run_dir", type=Path, metavar="RUN_DIR", help="run directory written by reach_jax.train")
    p.add_argument("--checkpoint", type=Path, metavar="PATH", help="evaluate this checkpoint instead of the newest")
    p.add_argument("--out", type=Path, metavar="DIR", help="write the results here instead of RUN_DIR/eval")
    p.add_argument(
        "--claims-only",
        action="store_true",
        help="decide the claims again from RUN_DIR/eval's files (claims.json/.md, table2.md), without new episodes",
    )
    p.add_argument(
        "--animate",
        nargs="?",
        const=True,
        type=Path,
        metavar="GIF",
        help="only write a GIF of a no-field network's corner movements without and with the field "
        "(default RUN_DIR/eval/reaching.gif)",
    )
    return p


def evaluate_main(argv=None) -> int:
    """`python -m reach_jax.evaluate`; returns the exit status."""
    parser = build_evaluate_parser()
    try:
        args = parser.parse_args(argv)
        if args.claims_only:
            if args.checkpoint or args.out:
                raise UsageError("--claims-only reads and rewrites RUN_DIR/eval: no --checkpoint or --out")
            evaluate.redecide(args.run_dir)
            print(f"claims decided again in {Path(args.run_dir) / evaluate.EVAL_DIR}", file=sys.stderr)
            return 0
        distribute.setup_backend(1)  # the evaluation does not shard: one device, as the evaluate CLI always had
        if args.animate is not None:
            try:
                gif = animation.animate(args.run_dir, None if args.animate is True else args.animate)
            except ValueError as exc:  # the run has no network of the condition to show
                raise UsageError(str(exc)) from None
            print(f"animation written to {gif}", file=sys.stderr)
            return 0
        run = run_dir_io.load(args.run_dir, args.checkpoint)
    except (UsageError, CheckpointError) as exc:
        sys.stderr.write(error_line(parser.prog, str(exc)))
        return EXIT_USAGE
    results = evaluate.evaluate_run(run)
    out = args.out or Path(args.run_dir) / evaluate.EVAL_DIR
    try:
        evaluate.write_results(args.run_dir, run, results, out)
    except OSError as exc:
        sys.stderr.write(error_line(parser.prog, f"{out}: write failed ({exc})"))
        return EXIT_IO
    print(f"evaluation written to {out}", file=sys.stderr)
    return 0
