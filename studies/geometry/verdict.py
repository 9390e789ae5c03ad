"""Issue 62's adoption verdict (studies/geometry/PLAN.md), from the held-out geometry run's committed evaluation.

    python studies/geometry/verdict.py runs/geometry_heldout --out studies/geometry/verdict

One record per visual field and bound, in the mirrored frame, read as the map reads them (`map.py`'s `points`):
collapsed networks, stable learners, D, the claims that hold, the paper's plausible cells. The comparator is
today's field and bound (COMPARATOR); a candidate qualifies with no collapsed network, at least STABLE of its
learners stable, a lower D and at least as many claims holding; the qualifying candidate with the lowest D is
adopted. Issue 62's targets are then checked on the adopted point (the comparator when none is adopted), beside the
rule. Writes OUT.json, OUT.md and OUT_table2.md (that point's Table 2 in the judged frame, from its committed
evaluation).
"""

from __future__ import annotations

import argparse
import importlib.util
import json
from pathlib import Path

import numpy as np

SCRIPT = "studies/geometry/verdict.py"
COMPARATOR = {"centre_m": (-0.05, 0.37), "cell_m": 0.04, "noise": 0.2}  # config version 15's field [m] and bound
STABLE = 30  # of 32 learners (PLAN.md)
TARGETS = {"D": 15.0, "plausible_cells": 6}  # issue 62's targets, reported beside the rule, not deciding
FRAME = "viscous_mirror"  # the frame the run trained in and the rule judges
HOLD = (1, 2, 3, 4)  # issue 62's target: these claims hold, and claim 5 at least in part


def _map():
    """studies/geometry/map.py (the studies are scripts, not a package)."""
    spec = importlib.util.spec_from_file_location("geometry_map", Path(__file__).with_name("map.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def is_comparator(p: dict) -> bool:
    """Whether a point is today's field and bound."""
    return all(bool(np.allclose(p[k], v)) for k, v in COMPARATOR.items())


def failures(p: dict, comparator: dict) -> list[str]:
    """The rule's conditions that the candidate `p` misses against `comparator`, in words; empty if it qualifies."""
    why = []
    if p["collapsed"]:
        why.append(f"{p['collapsed']} network(s) collapsed")
    if p["stable"] < STABLE:
        why.append(f"{p['stable']} of {p['learners']} learners stable (< {STABLE})")
    if p["D"] >= comparator["D"]:
        why.append(f"D {p['D']:.1f} not below the comparator's {comparator['D']:.1f}")
    if p["holding"] < comparator["holding"]:
        why.append(f"{p['holding']} claims holding, fewer than the comparator's {comparator['holding']}")
    return why


def decide(pts: list[dict]) -> dict:
    """The comparator, every candidate with what it misses (lowest D first), the adopted one (None: none) and issue
    62's targets as the default then stands (`targets_met`)."""
    (comparator,) = [p for p in pts if is_comparator(p)]
    candidates = sorted((p for p in pts if not is_comparator(p)), key=lambda p: p["D"])
    judged = [{**p, "fails": failures(p, comparator)} for p in candidates]
    adopted = next((p for p in judged if not p["fails"]), None)
    met = targets_met(comparator if adopted is None else adopted)
    return {"comparator": comparator, "candidates": judged, "adopted": adopted, "targets": TARGETS, "met": met}


def targets_met(p: dict) -> dict[str, bool]:
    """Issue 62's targets for a point: D, the paper's plausible cells, and the claims (HOLD holding, 5 at least in
    part)."""
    plausible = p["plausible_cells"] is not None and p["plausible_cells"] >= TARGETS["plausible_cells"]
    claims = all(p["claims"][k] == "holds" for k in HOLD) and p["claims"][5] != "does not hold"
    return {"D": p["D"] <= TARGETS["D"], "plausible_cells": plausible, "claims": claims}


def _name(p: dict) -> str:
    return f"centre ({p['centre_m'][0]:+.3f}, {p['centre_m'][1]:.3f}) m, cell {p['cell_m']:.3f} m, bound {p['noise']:g}"


def _row(p: dict, role: str) -> str:
    plaus = "–" if p["plausible_cells"] is None else f"{p['plausible_cells']} of 8"
    claims = ", ".join(f"{k}: {v}" for k, v in sorted(p["claims"].items()))
    fails = "; ".join(p.get("fails", [])) or ("qualifies" if role == "candidate" else "")
    return (
        f"| {role} | {_name(p)} | {p['D']:.1f} | {plaus} | {p['holding']} ({claims}) | {p['stable']}/{p['learners']} "
        f"| {p['collapsed']} | {fails} |"
    )


def markdown(found: dict, command: str) -> str:
    """OUT.md: the rule's table and its outcome."""
    adopted = found["adopted"]
    outcome = (
        f"**Adopted: {_name(adopted)}**, D {adopted['D']:.1f} against the comparator's {found['comparator']['D']:.1f}."
        if adopted
        else "**No candidate qualifies: today's field and bound stay the default.**"
    )
    lines = [
        "# The geometry verdict (issue 62, studies/geometry/PLAN.md)",
        "",
        f"Made by `{command}` from the held-out run's committed evaluation, frame viscous_mirror. {outcome}",
        "",
        "| role | field and bound | D | plausible | claims holding | stable | collapsed | the rule |",
        "|---|---|---|---|---|---|---|---|",
        _row(found["comparator"], "comparator"),
        *(_row(p, "candidate") for p in found["candidates"]),
        "",
        f"Issue 62's targets, beside the rule, for the {'adopted point' if adopted else 'default'}: "
        + "; ".join(_target_words(found["met"]))
        + ".",
    ]
    return "\n".join(lines) + "\n"


def _target_words(met: dict[str, bool]) -> list[str]:
    words = {
        "D": f"D ≤ {TARGETS['D']:g}",
        "plausible_cells": f"the paper plausible in at least {TARGETS['plausible_cells']} of 8 cells",
        "claims": f"claims {', '.join(map(str, HOLD))} holding and 5 at least in part",
    }
    return [f"{words[k]}: {'met' if ok else 'not met'}" for k, ok in met.items()]


def table2(run: Path, p: dict) -> str:
    """OUT_table2.md: the point's Table 2 in FRAME, the section of its folder's committed table2.md."""
    text = (run / "eval" / p["folder"] / "table2.md").read_text()
    sections = text.split("\n## ")
    head = f"Frame {FRAME}, Recipe {p['recipe']}:"
    (section,) = [s for s in sections[1:] if s.startswith(head)]
    title = f"# Table 2 — {run}, {_name(p)} (studies/geometry/verdict.md)"
    return "\n\n".join([title, sections[0].split("\n", 1)[1].strip(), "## " + section.strip()]) + "\n"


def main(argv=None) -> None:
    """Command line."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("run", type=Path, help="the evaluated held-out run of several visual fields")
    p.add_argument("--out", type=Path, required=True, help="write OUT.json and OUT.md")
    args = p.parse_args(argv)
    found = decide(_map().points(args.run))
    command = f"python {SCRIPT} {args.run} --out {args.out}"
    args.out.with_suffix(".json").write_text(json.dumps(found, indent=2) + "\n")
    args.out.with_suffix(".md").write_text(markdown(found, command))
    shown = found["adopted"] or found["comparator"]
    args.out.with_name(args.out.name + "_table2.md").write_text(table2(args.run, shown))
    print(markdown(found, command).splitlines()[2])


if __name__ == "__main__":
    main()
