"""The flags of `python -m reach_jax.train`: their groups, argument types and help (`build_train_parser`).

Every hyperparameter of `config.hyper.TABLE` beyond --lr, --noise and --lam comes through --sweep.
"""

from __future__ import annotations

import argparse
import functools
import json
import sys
from pathlib import Path

from reach_jax import train
from reach_jax.config import (
    CONDITIONS,
    TRAINED_CONDITIONS,
    hyper,
    tuplify,
)
from reach_jax.config.hyperparameter import Hyperparameter
from reach_jax.config.overlay import PAPER_HYPER
from reach_jax.config.schema import DEFAULT_SPEED, ENGINES, MAX_HIDDEN_PAD
from reach_jax.engine import distribute
from reach_jax.errors import (
    Parser,
    non_negative_int,
    positive_int,
    whole_number,
)

ENGINE_HELP = "the step loop's engine: native (C++, CPU), jax, or auto (native where it runs); same bits (default auto)"


def _hidden_pad(text: str) -> int:
    return whole_number(text, 1, MAX_HIDDEN_PAD)


def _conditions(text: str) -> tuple[str, ...]:
    return tuple(n for n in text.replace(",", " ").split() if n)


def _values(h: Hyperparameter, text: str) -> tuple[float, ...]:
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
    _add_core_arguments(core)
    _add_hyper_arguments(core)
    _add_infrastructure_arguments(p.add_argument_group("infrastructure", "devices, chunking and logging, multi-host"))
    return p


def _add_core_arguments(core) -> None:
    """What to train and where: the config, the batch's shape, the seed and the run directory."""
    core.add_argument("-h", "--help", action="help", help="show this help and exit")
    core.add_argument("--config", type=Path, metavar="FILE", help="start from this config (JSON, as in config.json)")
    core.add_argument("--trials", type=positive_int, help="trials per learner (2e6 in the paper)")
    core.add_argument("--seeds", type=positive_int, help="networks per condition (2 in the paper)")
    core.add_argument(
        "--conditions",
        type=_conditions,
        help=f"comma-separated names from the conditions table (default {','.join(TRAINED_CONDITIONS)}: the "
        f"paper's {','.join(CONDITIONS)} with its field mirrored, model §6; add one with --config FILE or --set "
        "conditions.NAME.FIELD=JSON)",
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


def _add_hyper_arguments(core) -> None:
    """The hyperparameters: the paper's three by name, any other by --sweep, and their table."""
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


def _add_infrastructure_arguments(infra) -> None:
    """How the run is carried out, none of which changes its results: devices, chunks, logs, several processes."""
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
    infra.add_argument("--engine", choices=ENGINES, default=DEFAULT_SPEED.engine, help=ENGINE_HELP)
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
