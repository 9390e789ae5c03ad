"""The claims as Markdown: per recipe, the five claims with their numbers in words, the Table-2 cells, the checks.

Units as in `claims`: success and out in percentage points, times [s], damping [N s/m]. `summary_text` is the
screen that the evaluate command ends with.
"""

from __future__ import annotations

import shlex
from pathlib import Path

from reach_jax.evaluate import collapse, frames, plausibility


def paper_cells(cells: list[dict]) -> tuple[list[dict], list[dict]]:
    """A recipe's Table-2 cells (its `claims.json` entries) that the paper has, and of those the ones near it.

    Args:
        cells: the recipe's `cells` in `eval/claims.json`; `near_paper` is empty for a cell the paper lacks.
    """
    judged = [cell for cell in cells if cell["near_paper"]]
    return judged, [cell for cell in judged if all(cell["near_paper"].values())]


def interval_text(ci: dict, few: int, scale: float = 1.0, digits: int = 1, unit: str = "") -> str:
    """A mean with its interval, "mean [low, high]", or with each network's value, "mean (networks a, b)", where
    there are fewer than `few` networks (or no interval); "–" without a value.

    Args:
        ci: a `stats` interval: mean, low, high, n and the networks' values.
        few: `informative_networks` of the claims' criteria.
        scale: multiplies every number (100 for percentages).
        digits: decimals shown.
        unit: written after the mean.
    """
    if ci["mean"] is None:
        return "–"
    text = f"{ci['mean'] * scale:.{digits}f}{unit}"
    values = ci.get("values", [])
    if ci["n"] < few or ci["low"] is None:
        if len(values) > 1:
            text += " (networks " + ", ".join(f"{v * scale:.{digits}f}" for v in values) + ")"
        return text
    return text + f" [{ci['low'] * scale:.{digits}f}, {ci['high'] * scale:.{digits}f}]"


def _fmt(name: str, value, few: int = 0) -> str:
    """One number of a claim in words, in the unit its name implies (`interval_text`)."""
    if isinstance(value, dict) and "mean" in value:
        if value["mean"] is None:
            return "–"
        if "ratio" in name:
            scale, unit, digits = 1.0, "×", 2
        elif "deg" in name:
            scale, unit, digits = 1.0, "°", 0
        elif "success" in name and "change" not in name:
            scale, unit, digits = 100.0, "%", 1
        else:
            scale, unit, digits = 100.0, " pts", 1
        return interval_text({"n": 1, "low": None, **value}, few, scale, digits, unit)
    if value is None:
        return "–"
    if "fraction" in name or "paths_pulled" in name:
        return f"{value:.0%} of movements"
    if "deg" in name:
        return f"{value:.0f}°"
    return f"{value:.3g}"


def _paper_fmt(name: str, value: float) -> str:
    return _fmt(name, {"mean": value})


def claims_markdown(result: dict, source: str, anatomy: dict | None = None) -> str:
    """claims.json as Markdown: per frame of the field and recipe, the five claims with their numbers and verdicts,
    then the checks and the failure anatomy's line.

    Args:
        result: claims.json's record.
        source: the run and chunk named in the title.
        anatomy: {frame: one line per recipe} of the failure anatomy (`anatomy.headline`); none where absent.
    """
    lines = [f"# The paper's claims — {source}", ""]
    judged = {result.get("frame"): result, **result.get("frames", {})}
    if len(judged) > 1:
        lines += [frames.FRAMES_WORDS, ""]
    for frame, decided in judged.items():
        lines += _recipe_sections(decided["recipes"], frame, (anatomy or {}).get(frame, []))
    return "\n".join(lines)


def _recipe_sections(recipes: list[dict], frame: str | None, anatomy: list[str]) -> list[str]:
    """One frame's claims, a section per recipe, each with its line of `anatomy` where there is one."""
    lines = []
    for k, recipe in enumerate(recipes):
        name = ", ".join(f"{key} {v:g}" for key, v in recipe["hypers"].items())
        lines += [
            f"## {frames.heading(frame)}Recipe {k}: {name} ({recipe['networks_per_condition']} networks per condition)",
            "",
            f"Intervals are {recipe['level']:.0%} t-intervals over networks, on the logit scale for success and out"
            " rates and on the log scale for times and ratios; differences are paired by seed. " + _few_words(recipe),
            "",
            "| claim | test | ours | paper | verdict |",
            "|---|---|---|---|---|",
            *(_claim_row(c, recipe.get("informative_networks", 0)) for c in recipe["claims"]),
            "",
            *_checks(recipe),
            "",
            *([anatomy[k], ""] if k < len(anatomy) else []),
            *_damping_table(recipe, frame),
            "",
        ]
    return lines


def _claim_row(c: dict, few: int) -> str:
    """One claim as a table row: its statement, test, our numbers, the paper's and the verdict with its reason."""
    ours, paper = [], []
    for key, value in c["numbers"].items():
        inner = value.get("success", value) if isinstance(value, dict) and "success" in value else value
        label = f"{key}_success" if isinstance(value, dict) and "success" in value else key
        ours.append(f"{key.replace('_', ' ')}: {_fmt(label, inner, few)}")
        if isinstance(value, dict) and "paper" in value:
            paper.append(f"{key.replace('_', ' ')}: {_paper_fmt(label, value['paper'])}")
        elif key == "paper_angle_deg":
            ours.pop()
            paper.append(f"angle between pulls: {value:.0f}°")
    why = c["why"] + (
        f"; depends on collapsed networks: {collapse.names(c['collapsed'])}" if c.get("collapsed") else ""
    )
    cells = (
        f"{c['claim']}. {c['statement']}",
        c["test"],
        "; ".join(ours),
        "; ".join(paper),
        f"**{c['verdict']}**: {why}",
    )
    return "| " + " | ".join(cells) + " |"


def _checks(recipe: dict) -> list[str]:
    """The Table-2 target, the paper's plausibility (`plausibility.words`), the curriculum's stability and, where the
    evaluation named them, the collapsed networks."""
    judged, near = paper_cells(recipe["cells"])
    cur = recipe["curriculum"]
    unstable = [p["learner"] for p in cur["learners"] if p["tail_chunks"] and not p["stable"]]
    lines = [
        "Table-2 target (success and out within the target's points, time within its fraction, every cell): "
        f"{len(near)} of {len(judged)} cells.",
        *(["", "Plausibility: " + plausibility.words(recipe["plausibility"], recipe["D"])] if "D" in recipe else []),
        "",
        "Curriculum: " + _curriculum_words(cur, unstable),
    ]
    if "collapsed" in recipe:
        lines += ["", collapsed_words(recipe)]
    return lines


def collapsed_words(recipe: dict) -> str:
    """The sentence that names a recipe's collapsed networks (`collapsed` in claims.json), or says there are none."""
    rule = (
        f"success below {recipe['collapse_success']:.0%} in the test of their own learning condition, or of the null"
        " field where theirs is not tested"
    )
    if not recipe["collapsed"]:
        return f"Collapsed networks ({rule}): none."
    return f"**Collapsed networks** ({rule}): {collapse.names(recipe['collapsed'])}."


def _damping_table(recipe: dict, frame: str | None) -> list[str]:
    """The learned hand damping per cell along the field's axes, as a Markdown table with its lead-in."""
    few = recipe.get("informative_networks", 0)
    names = ("damping_unstable", "damping_stable", "passive_damping_unstable")
    return [
        "Learned hand damping (mean over networks of each network's median, N s/m) along the field's axes; the"
        " interval is on the log scale where every network's damping is positive, and plain where one is not"
        " (a learned damping can be negative):",
        "",
        "| learning → test | unstable axis | stable axis | passive, unstable axis |",
        "|---|---|---|---|",
        *(
            f"| {frames.shown(cell['learning'], frame)} → {frames.shown(cell['test'], frame)} | "
            + " | ".join(interval_text(cell[n], few) for n in names)
            + " |"
            for cell in recipe["impedance"]
        ),
    ]


def _curriculum_words(cur: dict, unstable: list[int]) -> str:
    n = len(cur["learners"])
    if cur["all_stable"]:
        return f"every one of the {n} learners stayed at the whole field late in training."
    text = f"{cur['judged']} of {n} learners have reached the last part of training"
    if unstable:
        text += f"; learners {', '.join(map(str, unstable))} fell back below the bound too often there"
    return text + "."


def _few_words(recipe: dict) -> str:
    """The sentence that says when a network's own values stand in for an interval."""
    few = recipe.get("informative_networks", 0)
    if recipe["networks_per_condition"] >= few:
        return ""
    return (
        f"With {recipe['networks_per_condition']} networks a condition (fewer than {few}) an interval says little,"
        " so each network's value stands beside the mean instead."
    )


SHORT = {"holds": "holds", "holds in part": "part", "does not hold": "no"}  # a verdict in a few letters
SUMMARY_SECTIONS = 4  # frame x recipe sections on the closing screen; claims.md and compare have the rest
# The files worth opening first, in order, with what each shows; those the evaluation wrote are listed.
SUMMARY_FILES = {
    "table2.md": "Table 2 beside the paper's, with our pairs' ranges",
    "claims.md": "the five claims with their numbers and verdicts",
    "anatomy.md": "how the failing movements fail",
    "fig4.png": "Fig. 4: corner movements without and with the field",
    "learning_curves.png": "learning curves",
    "adaptation.md": "adaptation over the protocols' trials",
}


def summary_text(results: dict, run_dir: Path, out: Path, failures: dict | None = None) -> str:
    """The closing screen of `python -m reach_jax.evaluate`: per frame and recipe the claims' verdicts, the cells
    near the paper, D and the paper's plausibility and the failures' headline; the files to open; what to run next.

    Args:
      results: the evaluation's results keyed by file (`run.Results.json`); "claims" is read.
      run_dir: the evaluated run.
      out: the folder the files were written to; the `SUMMARY_FILES` found there are listed.
      failures: {frame: one line per recipe} of the failure anatomy (`anatomy_report.headlines(..., plain=True)`);
        none where absent.
    """
    claims = results["claims"]
    judged = {claims.get("frame"): claims, **claims.get("frames", {})}
    sections = [(frame, k, recipe) for frame, decided in judged.items() for k, recipe in enumerate(decided["recipes"])]
    lines = [f"{run_dir} at chunk {claims['chunk']}:"]
    for frame, k, recipe in sections[:SUMMARY_SECTIONS]:
        verdicts = " · ".join(f"{c['claim']} {SHORT[c['verdict']]}" for c in recipe["claims"]) or "none decided"
        cells, near = paper_cells(recipe["cells"])
        collapsed = f"; {len(recipe['collapsed'])} networks collapsed" if recipe.get("collapsed") else ""
        lines += [
            f"{frames.heading(frame)}recipe {k} ({recipe['networks_per_condition']} networks a condition): "
            f"claims {verdicts}{collapsed}",
            f"  Table 2: {len(near)} of {len(cells)} cells near the paper" + _plausible_cells(recipe),
            "  " + _plausible_table(recipe),
            *([f"  Failures, {line}"] if (line := _at((failures or {}).get(frame, []), k)) else []),
        ]
    if len(sections) > SUMMARY_SECTIONS:
        lines.append(f"… and {len(sections) - SUMMARY_SECTIONS} more frame and recipe sections in claims.md")
    shown = [name for name in SUMMARY_FILES if (Path(out) / name).is_file()]
    width = max(map(len, shown), default=0)
    lines += ["Open:", *(f"  {Path(out) / name}{' ' * (width - len(name))}  {SUMMARY_FILES[name]}" for name in shown)]
    lines.append(
        f"Next: python -m reach_jax.evaluate.compare {shlex.quote(str(run_dir))} [OTHER_RUN ...] sets runs side by"
        " side; docs/claims.md says how each verdict is decided."
    )
    return "\n".join(lines)


def _at(lines: list[str], k: int) -> str:
    return lines[k] if k < len(lines) else ""


def _plausible_cells(recipe: dict) -> str:
    """The cells in which the paper is a plausible two-network draw from ours, for the closing screen."""
    record = recipe.get("plausibility")
    if record is None:
        return ""
    return f"; the paper plausible in {record['plausible_cells']} of {len(record['cells'])}"


def _plausible_table(recipe: dict) -> str:
    """D and whether the paper's table as a whole is plausible (`plausibility.judge`), for the closing screen."""
    record = recipe.get("plausibility")
    if record is None:
        d = recipe.get("D")
        return f"D {'–' if d is None else f'{d:.1f}'} points (plausibility needs {plausibility.MIN_NETWORKS} networks)"
    pd = record["pairs_D"]
    verdict = "is" if record["plausible"] else "is not"
    return (
        f"D {record['D']:.1f} points, our pairs' {pd['low']:.1f}–{pd['high']:.1f} ({record['level']:.0%}): the"
        f" paper's table {verdict} a plausible draw of two networks from ours"
    )
