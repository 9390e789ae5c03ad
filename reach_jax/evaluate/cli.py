"""The command line `python -m reach_jax.evaluate`: a run directory in, its eval/ files out (`evaluate.evaluate_run`).

Every user error prints one line, "prog: error: message", and exits 2 with nothing written. An evaluation ends with
one screen (`report.summary_text`): the claims' verdicts, D, the paper's plausibility and the failures' headline,
the files to open.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from reach_jax import evaluate
from reach_jax.engine import distribute
from reach_jax.errors import EXIT_IO, EXIT_USAGE, Parser, UsageError, error_line, printable
from reach_jax.evaluate import anatomy_report, animation, geometry, report
from reach_jax.store import run_dir as run_dir_io
from reach_jax.store import run_lock
from reach_jax.store.checkpoint import CheckpointError


def build_evaluate_parser() -> argparse.ArgumentParser:
    """The command-line interface of `python -m reach_jax.evaluate`."""
    p = Parser(prog="python -m reach_jax.evaluate", description=evaluate.__doc__.splitlines()[0])
    p.add_argument("run_dir", type=Path, metavar="RUN_DIR", help="run directory written by reach_jax.train")
    p.add_argument("--checkpoint", type=Path, metavar="PATH", help="evaluate this checkpoint instead of the newest")
    p.add_argument("--out", type=Path, metavar="DIR", help="write the results here instead of RUN_DIR/eval")
    p.add_argument(
        "--animate",
        nargs="?",
        const=True,
        type=Path,
        metavar="GIF",
        help="only write a GIF of a no-field network's corner movements without and with the field "
        "(default RUN_DIR/eval/reaching.gif)",
    )
    p.add_argument(
        "--claims-only",
        action="store_true",
        help="decide the claims again from RUN_DIR/eval's files (claims.json/.md, table2.md), without new episodes",
    )
    return p


def main(argv=None) -> int:
    """`python -m reach_jax.evaluate`; returns the exit status."""
    parser = build_evaluate_parser()
    try:
        args = parser.parse_args(argv)
        if args.claims_only:
            if args.checkpoint or args.out:
                raise UsageError("--claims-only reads and rewrites RUN_DIR/eval: no --checkpoint or --out")
            claims = evaluate.redecide(args.run_dir)
            out = Path(args.run_dir) / evaluate.EVAL_DIR
            anat = out / "anatomy.json"
            failures = anatomy_report.headlines(json.loads(anat.read_text()), plain=True) if anat.is_file() else None
            print(report.summary_text({"claims": claims}, args.run_dir, out, failures), file=sys.stderr)
            print(f"claims decided again in {out}", file=sys.stderr)
            return 0
        distribute.setup_backend(1)  # the evaluation does not shard: one device, as the evaluate CLI always had
        if args.animate is not None:
            try:
                gif = animation.animate(args.run_dir, None if args.animate is True else args.animate)
            except ValueError as exc:  # the run has no network of the condition to show
                raise UsageError(str(exc)) from None
            print(f"animation written to {gif}", file=sys.stderr)
            return 0
        live = run_lock.holder(args.run_dir)
        run = run_dir_io.load(args.run_dir, args.checkpoint)
    except (UsageError, CheckpointError) as exc:
        sys.stderr.write(error_line(parser.prog, str(exc)))
        return EXIT_USAGE
    if live is not None:
        note = f"{args.run_dir} is still training ({live}); evaluating its checkpoint after chunk {run.chunk}"
        sys.stderr.write(f"{parser.prog}: {printable(note)}\n")
    return _evaluate_and_write(args, run, parser.prog)


def _evaluate_and_write(args, run, prog: str) -> int:
    """Evaluate a loaded run, write its files and print the closing screen; returns the exit status."""
    out = args.out or Path(args.run_dir) / evaluate.EVAL_DIR
    several = len(geometry.groups(run)) > 1
    try:
        if several:
            evaluate.evaluate_fields(args.run_dir, run, out)
        else:
            results = evaluate.evaluate_run(run)
            evaluate.write_results(args.run_dir, run, results, out)
    except OSError as exc:
        sys.stderr.write(error_line(prog, f"{out}: write failed ({exc})"))
        return EXIT_IO
    if several:
        index = out / f"{geometry.INDEX}.md"
        print(f"{args.run_dir}: each visual field evaluated as a run of its own; {index} lists them", file=sys.stderr)
        print(f"evaluation written to {out}", file=sys.stderr)
        return 0
    failures = anatomy_report.headlines(results.json["anatomy"], plain=True)
    print(report.summary_text(results.json, args.run_dir, out, failures), file=sys.stderr)
    print(f"evaluation written to {out}", file=sys.stderr)
    return 0
