"""The failure anatomy in words and in a figure: anatomy.md, anatomy.png and the claims report's line; shares in %.

Reads `anatomy.summarize`'s record (anatomy.json), so that `judgements.redecide` can write the claims report's line
again from the committed file.
"""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

from reach_jax.evaluate import frames
from reach_jax.evaluate.anatomy import FAIL_CLASSES, LABELS, OUT_LIMITS, by_frame
from reach_jax.evaluate.report import interval_text

# How the Markdown, the figure and the claims report name the labels; an out's, with its limit (`words`).
WORDS = {
    "success": "success",
    "theta1_low": "θ1 < {:g}°",
    "theta1_high": "θ1 > {:g}°",
    "theta2_low": "θ2 < {:g}°",
    "folded": "folded",
    "chatter": "chatter",
    "hover": "hover",
    "rest_near": "rest near",
    "rest_far": "rest far",
    "swinging": "swinging",
}
COLORS = {
    "success": "#4daf4a",
    "theta1_low": "#fcae91",
    "theta1_high": "#fb6a4a",
    "theta2_low": "#cb181d",
    "folded": "#54278f",
    "chatter": "#ff7f00",
    "hover": "#ffd92f",
    "rest_near": "#9ecae1",
    "rest_far": "#3182bd",
    "swinging": "#969696",
}


def words(anatomy: dict) -> dict:
    """{label: its name in words}, an out's with the limit it crossed [deg] (anatomy.json's "limits_deg")."""
    return {k: w.format(anatomy["limits_deg"].get(k, 0.0)) for k, w in WORDS.items()}


def _composition(shares: dict, names: tuple[str, ...], said: dict) -> str:
    """ "73% folded, 12% swinging" from pooled shares, largest first, those under half a percent left out."""
    seen = sorted(((shares[k], k) for k in names if shares[k] is not None and shares[k] >= 0.005), reverse=True)
    return ", ".join(f"{s:.0%} {said[k]}" for s, k in seen)


def _headline_cell(cells: list[dict]) -> dict | None:
    """The cell a claims report's line is about: the unexpected field (none → viscous), else the most fails."""
    for c in cells:
        if (c["learning"], c["test"]) == ("none", frames.PAPER_FIELD):
            return c
    return max(cells, key=lambda c: sum(c["counts"][k] for k in FAIL_CLASSES), default=None)


def headline(anatomy: dict, frame: str | None, recipe: int) -> str:
    """One line for the claims report: a recipe's unexpected field's fails by class and outs by limit in a frame.

    Args:
      anatomy: `anatomy.summarize` results.
      frame: the frame (a key of `by_frame`).
      recipe: the recipe's index.
    """
    body = plain_headline(anatomy, frame, recipe)
    # The file is named, not linked: the docs pages copy claims.md in, where a link would point nowhere.
    return f"**Failure anatomy** (`anatomy.md`), {body}" if body else "Failure anatomy: no cell."


def plain_headline(anatomy: dict, frame: str | None, recipe: int) -> str:
    """`headline`'s words without its Markdown, as a terminal shows them; "" where the recipe has no cell."""
    c, said = _headline_cell(by_frame(anatomy)[frame][recipe]["cells"]), words(anatomy)
    if c is None:
        return ""
    name = f"{frames.shown(c['learning'], frame)} → {frames.shown(c['test'], frame)}"
    fails, outs = (sum(c["counts"][k] for k in group) / c["movements"] for group in (FAIL_CLASSES, OUT_LIMITS))
    text = f"{name}: {fails:.1%} of movements fail"
    if fails:
        text += f" ({_composition(c['of_fails'], FAIL_CLASSES, said)}; {c['fails_in_goal']:.0%} in the goal square)"
    text += f", {outs:.1%} go out"
    if outs:
        text += f" ({_composition(c['of_outs'], OUT_LIMITS, said)}; median {c['out_time_s']['median']:.2f} s)"
    return text + "."


def headlines(anatomy: dict, plain: bool = False) -> dict:
    """{frame: the claims report's line (`headline`, or `plain_headline`) for each recipe} of an anatomy.json record."""
    line = plain_headline if plain else headline
    return {f: [line(anatomy, f, k) for k in range(len(rs))] for f, rs in by_frame(anatomy).items()}


def _row(c: dict, frame: str | None, names: tuple[str, ...], few: int, of: str | None) -> str:
    """A Markdown row: each label's share of movements with its interval, and its share of the group (`of`)."""
    texts = []
    for k in names:
        text = interval_text(c["shares"][k], few, 100.0)
        if of is not None and c[of].get(k) is not None:
            text += f" ({c[of][k]:.0%})"
        texts.append(text)
    head = f"| {frames.shown(c['learning'], frame)} → {frames.shown(c['test'], frame)} | {c['networks']} | "
    return head + " | ".join(texts)


def markdown(anatomy: dict, source: str, few: int) -> str:
    """anatomy.json as Markdown: per frame and recipe, a table of the outs by limit and one of the fails by class.

    Args:
      anatomy: `summarize` results.
      source: the run and chunk named in the title.
      few: below this many networks a cell shows each network's value instead of an interval.
    """
    t = anatomy["thresholds"]
    lines = [
        f"# Failure anatomy — {source}",
        "",
        "Each cell: the share of a network's movements, % (mean over networks with its 95% t-interval on the logit"
        " scale), and in brackets the share of the cell's outs or fails, pooled over its networks. An out is named by"
        " the joint limit it crossed; a fail by the first class that fits its last"
        f" {t['anatomy_window']:g} s: folded (the elbow within {t['anatomy_fold_margin_deg']:g}° of its stop in"
        f" {t['anatomy_fold_share']:.0%} of the states or more), chatter (a joint's torque changes sign, above"
        f" {t['anatomy_flip_torque']:g} N m, in {t['anatomy_chatter_share']:.0%} of the steps or more), hover (the"
        f" hand inside the goal square in {t['anatomy_hover_share']:.0%} of the states or more, too fast to stop"
        f" there), rest near or far (mean hand speed below {t['anatomy_rest_speed']:g} m/s, ending within"
        f" {t['anatomy_near_cells']:g} cells of the target or not), swinging (the rest: still moving)."
        " docs/claims.md describes the classes.",
    ]
    said = words(anatomy)
    for frame, recipes in by_frame(anatomy).items():
        for k, recipe in enumerate(recipes):
            name = ", ".join(f"{key} {v:g}" for key, v in recipe["hypers"].items())
            lines += ["", f"## {frames.heading(frame)}Recipe {k}: {name}", *_tables(recipe["cells"], frame, few, said)]
    return "\n".join(lines) + "\n"


def _tables(cells: list[dict], frame: str | None, few: int, said: dict) -> list[str]:
    """A recipe's two tables in a frame: success and the outs by limit, then the fails by class."""
    lines = [
        "",
        "| learning → test | networks | success % | "
        + " | ".join(f"out, {said[k]} %" for k in OUT_LIMITS)
        + " | outs' median time [s] (quartiles) |",
        "|---|---|---|" + "---|" * len(OUT_LIMITS) + "---|",
    ]
    for c in cells:
        med, t = c["out_time_s"]["median"], c["out_time_s"]
        timed = "–" if med is None else f"{med:.2f} ({t['q1']:.2f}–{t['q3']:.2f})"
        lines.append(_row(c, frame, ("success", *OUT_LIMITS), few, "of_outs") + f" | {timed} |")
    lines += [
        "",
        "| learning → test | networks | "
        + " | ".join(f"fail, {said[k]} %" for k in FAIL_CLASSES)
        + " | fails in the goal square |",
        "|---|---|" + "---|" * len(FAIL_CLASSES) + "---|",
    ]
    for c in cells:
        goal = "–" if c["fails_in_goal"] is None else f"{c['fails_in_goal']:.0%}"
        lines.append(_row(c, frame, FAIL_CLASSES, few, "of_fails") + f" | {goal} |")
    return lines


def figure(anatomy: dict) -> Figure:
    """Stacked bars, one per cell and a panel per frame: the mean share of each label, success to swinging.

    Args:
      anatomy: `summarize` results.
    """
    panels, said = by_frame(anatomy), words(anatomy)
    bars = {f: [(k, c) for k, recipe in enumerate(recipes) for c in recipe["cells"]] for f, recipes in panels.items()}
    rows = sum(len(b) for b in bars.values())
    fig = Figure(figsize=(10, 1.2 + 0.32 * rows + 0.9 * len(panels)))
    heights = [max(len(b), 1) for b in bars.values()]
    axes = fig.subplots(len(panels), 1, squeeze=False, gridspec_kw={"height_ratios": heights})[:, 0]
    recipes_shown = max(len(r) for r in panels.values()) > 1
    legend = {k: ("out: " if k in OUT_LIMITS else "fail: " if k in FAIL_CLASSES else "") + said[k] for k in LABELS}
    for ax, (frame, cells) in zip(axes, bars.items(), strict=True):
        names = [
            (f"r{k}: " if recipes_shown else "")
            + f"{frames.shown(c['learning'], frame)} → {frames.shown(c['test'], frame)}"
            for k, c in cells
        ]
        left = np.zeros(len(cells))
        for label in LABELS:
            width = np.array([100.0 * (c["shares"][label]["mean"] or 0.0) for _, c in cells])
            ax.barh(np.arange(len(cells)), width, left=left, color=COLORS[label], label=legend[label], height=0.75)
            for y, (x, w) in enumerate(zip(left, width, strict=True)):
                if w >= 6.0:  # a share too thin for its number is left to the legend
                    ax.text(x + w / 2, y, f"{w:.0f}", ha="center", va="center", fontsize=7)
            left += width
        ax.set_yticks(np.arange(len(cells)), names, fontsize=8)
        ax.invert_yaxis()
        ax.set_xlim(0, 100)
        ax.set_title(f"{frames.heading(frame).rstrip(', ') or 'Tests'}: where the movements end", fontsize=9)
    axes[-1].set_xlabel("share of a network's movements, % (mean over networks)")
    handles, names = axes[0].get_legend_handles_labels()
    fig.legend(handles, names, loc="lower center", ncol=len(LABELS) // 2, fontsize=7, frameon=False)
    fig.tight_layout(rect=(0, 0.07, 1, 1))
    return fig
