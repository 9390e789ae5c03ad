"""studies/geometry/verdict.py: issue 62's adoption rule, applied to points as the map reads them."""

from __future__ import annotations

import pytest


def point(centre, d, cell=0.04, noise=0.2, holding=3, stable=32, collapsed=0):
    """A map point (`studies/geometry/map.py`'s `points`) with what the rule reads."""
    claims = {k: "holds" if k <= holding else "does not hold" for k in range(1, 6)}
    return {
        "centre_m": list(centre), "cell_m": cell, "noise": noise, "D": d, "plausible_cells": 3, "claims": claims,
        "holding": holding, "stable": stable, "learners": 32, "collapsed": collapsed,
    }  # fmt: skip


def test_the_lowest_qualifying_d_is_adopted(load_tool):
    verdict = load_tool("studies/geometry/verdict")
    pts = [
        point((-0.05, 0.37), 20.0),
        point((0.10, 0.45), 12.0, collapsed=1),  # lowest D, but a network collapsed
        point((0.025, 0.41), 14.0, stable=29),  # too few stable
        point((0.05, 0.37), 16.0),  # qualifies
        point((-0.05, 0.37), 17.0, noise=0.25),  # qualifies, higher D
        point((-0.05, 0.45), 15.0, holding=2),  # fewer claims holding
    ]
    got = verdict.decide(pts)
    assert got["comparator"]["D"] == 20.0
    assert got["adopted"]["centre_m"] == [0.05, 0.37]
    fails = {p["D"]: p["fails"] for p in got["candidates"]}
    assert "collapsed" in fails[12.0][0] and "stable" in fails[14.0][0] and "claims" in fails[15.0][0]
    assert fails[16.0] == [] and fails[17.0] == []
    assert [p["D"] for p in got["candidates"]] == sorted(fails)
    assert "**Adopted: centre (+0.050, 0.370) m, cell 0.040 m, bound 0.2**" in verdict.markdown(got, "cmd")


@pytest.mark.parametrize("change", [{"d": 21.0}, {"d": 20.0}, {"holding": 2}, {"collapsed": 2}])
def test_nothing_is_adopted_unless_every_condition_holds(load_tool, change):
    verdict = load_tool("studies/geometry/verdict")
    d = change.pop("d", 10.0)
    got = verdict.decide([point((-0.05, 0.37), 20.0), point((0.10, 0.45), d, **change)])
    assert got["adopted"] is None and got["candidates"][0]["fails"]
    assert "No candidate qualifies" in verdict.markdown(got, "cmd")


def test_issue_62s_targets_are_checked_on_the_adopted_point(load_tool):
    verdict = load_tool("studies/geometry/verdict")
    good = {**point((-0.05, 0.37), 14.0, holding=4), "plausible_cells": 6}
    good["claims"][5] = "holds in part"
    assert verdict.targets_met(good) == {"D": True, "plausible_cells": True, "claims": True}
    assert verdict.targets_met({**good, "D": 15.5})["D"] is False
    assert verdict.targets_met({**good, "plausible_cells": 5})["plausible_cells"] is False
    assert verdict.targets_met({**good, "plausible_cells": None})["plausible_cells"] is False
    assert verdict.targets_met({**good, "claims": {**good["claims"], 5: "does not hold"}})["claims"] is False
    assert verdict.targets_met({**good, "claims": {**good["claims"], 3: "holds in part"}})["claims"] is False
    got = verdict.decide([point((-0.05, 0.37), 20.0), {**good, "centre_m": [0.1, 0.45]}])
    assert got["adopted"]["D"] == 14.0 and all(got["met"].values())
    assert "for the adopted point: D ≤ 15: met;" in verdict.markdown(got, "cmd")


def test_the_shown_table_is_the_points_section_of_its_fields_table(load_tool, tmp_path):
    verdict = load_tool("studies/geometry/verdict")
    folder = tmp_path / "eval" / "geometry_1"
    folder.mkdir(parents=True)
    frames = ("viscous_mirror", "viscous")
    sections = [f"## Frame {f}, Recipe {r}: x\n\n| row {f} {r} |" for f in frames for r in (0, 1)]
    (folder / "table2.md").write_text("# Table 2 — run\n\nThe intro.\n\n" + "\n\n".join(sections) + "\n")
    text = verdict.table2(tmp_path, {**point((0.0, 0.4), 9.0), "folder": "geometry_1", "recipe": 1})
    assert text.startswith("# Table 2 — ") and "The intro." in text
    assert "| row viscous_mirror 1 |" in text and "row viscous_mirror 0" not in text and "row viscous " not in text
