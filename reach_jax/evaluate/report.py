"""The claims as Markdown: per recipe, the five claims with their numbers in words, the Table-2 cells, the checks.

Units as in `claims`: success and out in percentage points, times [s], damping [N s/m].
"""

from __future__ import annotations


def paper_cells(cells: list[dict]) -> tuple[list[dict], list[dict]]:
    """A recipe's Table-2 cells (its `claims.json` entries) that the paper has, and of those the ones near it.

    Args:
        cells: the recipe's `cells` in `eval/claims.json`; `near_paper` is empty for a cell the paper lacks.
    """
    judged = [cell for cell in cells if cell["near_paper"]]
    return judged, [cell for cell in judged if all(cell["near_paper"].values())]


def _fmt(name: str, value) -> str:
    """One number of a claim in words: intervals as "mean [low, high]" in the unit its name implies."""
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
        text = f"{value['mean'] * scale:.{digits}f}{unit}"
        if value.get("low") is not None:
            text += f" [{value['low'] * scale:.{digits}f}, {value['high'] * scale:.{digits}f}]"
        return text
    if value is None:
        return "–"
    if "fraction" in name or "paths_pulled" in name:
        return f"{value:.0%} of movements"
    if "deg" in name:
        return f"{value:.0f}°"
    return f"{value:.3g}"


def _paper_fmt(name: str, value: float) -> str:
    return _fmt(name, {"mean": value})


def claims_markdown(result: dict, source: str) -> str:
    """claims.json as Markdown: per recipe, the five claims with their numbers and verdicts, then the checks."""
    lines = [f"# The paper's claims — {source}", ""]
    for k, recipe in enumerate(result["recipes"]):
        name = ", ".join(f"{key} {v:g}" for key, v in recipe["hypers"].items())
        lines += [
            f"## Recipe {k}: {name} ({recipe['networks_per_condition']} networks per condition)",
            "",
            f"Intervals are {recipe['level']:.0%} t-intervals over networks, on the logit scale for success and out"
            " rates; differences are paired by seed.",
            "",
            "| claim | test | ours | paper | verdict |",
            "|---|---|---|---|---|",
        ]
        for c in recipe["claims"]:
            ours, paper = [], []
            for key, value in c["numbers"].items():
                inner = value.get("success", value) if isinstance(value, dict) and "success" in value else value
                label = f"{key}_success" if isinstance(value, dict) and "success" in value else key
                ours.append(f"{key.replace('_', ' ')}: {_fmt(label, inner)}")
                if isinstance(value, dict) and "paper" in value:
                    paper.append(f"{key.replace('_', ' ')}: {_paper_fmt(label, value['paper'])}")
                elif key == "paper_angle_deg":
                    ours.pop()
                    paper.append(f"angle between pulls: {value:.0f}°")
            lines.append(
                f"| {c['claim']}. {c['statement']} | {c['test']} | {'; '.join(ours)} | {'; '.join(paper)} | "
                f"**{c['verdict']}**: {c['why']} |"
            )
        judged, near = paper_cells(recipe["cells"])
        cur = recipe["curriculum"]
        unstable = [p["learner"] for p in cur["learners"] if p["tail_chunks"] and not p["stable"]]
        lines += [
            "",
            f"Table-2 target (success and out within the target's points, time within its fraction, every cell): "
            f"{len(near)} of {len(judged)} cells.",
            "",
            "Curriculum: " + _curriculum_words(cur, unstable),
            "",
            "Learned hand damping (mean over networks of each network's median, N s/m) along the field's axes:",
            "",
            "| learning → test | unstable axis | stable axis | passive, unstable axis |",
            "|---|---|---|---|",
        ]
        for cell in recipe["impedance"]:
            dmp = [_interval_plain(cell[n]) for n in ("damping_unstable", "damping_stable", "passive_damping_unstable")]
            lines.append(f"| {cell['learning']} → {cell['test']} | " + " | ".join(dmp) + " |")
        lines.append("")
    return "\n".join(lines)


def _curriculum_words(cur: dict, unstable: list[int]) -> str:
    n = len(cur["learners"])
    if cur["all_stable"]:
        return f"every one of the {n} learners stayed at the whole field late in training."
    text = f"{cur['judged']} of {n} learners have reached the last part of training"
    if unstable:
        text += f"; learners {', '.join(map(str, unstable))} fell back below the bound too often there"
    return text + "."


def _interval_plain(ci: dict) -> str:
    if ci["mean"] is None:
        return "–"
    if ci["low"] is None:
        return f"{ci['mean']:.1f}"
    return f"{ci['mean']:.1f} [{ci['low']:.1f}, {ci['high']:.1f}]"
