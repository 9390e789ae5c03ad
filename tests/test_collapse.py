"""A collapsed learner is named wherever a user looks: the trainer's summary and bar, table2.md, claims.md, compare."""

from __future__ import annotations

import io
import json
import shutil
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from reach_jax.config import Config, TrainConfig, hyper
from reach_jax.evaluate import collapse, compare, judgements
from reach_jax.store import run_dir as run_dir_io
from reach_jax.train import health
from reach_jax.train.sinks import ProgressSink

ROOT = Path(__file__).resolve().parents[1]
CFG = Config(train=TrainConfig(trials=100_000, seeds=1, conditions=("none", "viscous", "random")))
LEARNERS = [("none", 0), ("viscous", 0), ("random", 0)]
FULL = health.whole_field(CFG)
START = CFG.task.curriculum_init_cells * CFG.sensor.cell_size


def learner_rows(chunk: int, before: dict) -> list[dict]:
    """Chunk `chunk` of three synthetic learners, 1,000 trials a chunk: 0 healthy; 1 collapses from chunk 60 (every
    trial out, the curriculum back at its start) after one bad chunk at 40 that it recovers from; 2 sets back in
    3 of the 20 chunks of its last 20% of trials, its success high throughout."""
    rows = []
    for i in range(3):
        success, distance = 0.98, min(FULL, START + chunk * 0.01)
        if i == 1 and (chunk == 40 or chunk >= 60):
            success, distance = 0.0, START if chunk >= 60 else distance
        if i == 2 and chunk in (85, 90, 95):
            distance = 0.5 * FULL
        trials = before.get(i, 0) + 1000
        before[i] = trials
        row = {"chunk": chunk, "learner": i, "trials": trials, "chunk_trials": 1000, "success_rate": success}
        rows.append({**row, "condition": LEARNERS[i][0], "seed": 0, **hyper.defaults(), "distance_m": distance})
    return rows


def synthetic_chunks() -> list[list[dict]]:
    seen: dict = {}
    return [learner_rows(chunk, seen) for chunk in range(1, 101)]


def test_the_trainers_health_names_the_collapse_and_the_late_setbacks_with_the_trial_they_began():
    h = health.Health(CFG, LEARNERS)
    for rows in synthetic_chunks()[:45]:
        h.update(rows)
    assert h.counts() == (0, 0)  # one bad chunk among ten thousand trials is not a collapse
    for rows in synthetic_chunks()[45:]:
        h.update(rows)
    assert [h.collapsed(i) for i in range(3)] == [False, True, False]
    assert [h.fell_back(i) for i in range(3)] == [False, True, True]  # 1 is named once, as collapsed
    assert h.summary() == [
        "learner 1 (viscous, seed 0) collapsed: success below 50% from trial 59,000",
        "learner 2 (random, seed 0) fell back: 3 of its last 20 chunks below the bound, the first from trial 84,000",
    ]
    # The stability verdict of the evaluation reads the same setbacks.
    assert h.state[2].tail_chunks == 20 and h.state[2].tail_setbacks == 3


def test_the_bar_counts_the_learners_collapsed_and_set_back_now():
    stream = io.StringIO()
    sink = ProgressSink(CFG.train.trials, health.Health(CFG, LEARNERS), 1, stream)
    sink.bar.min_interval = 0.0
    for rows in synthetic_chunks()[:95]:
        trials = np.array([r["trials"] for r in rows])
        states = SimpleNamespace(env=SimpleNamespace(trials=trials), counters=SimpleNamespace(steps=trials * 30))
        sink.chunk(SimpleNamespace(states=states, ran=3), rows)
    assert "| 1 collapsed, 1 set back" in stream.getvalue().splitlines()[-1]  # chunk 95: learner 2 below the bound


def test_a_run_directory_gives_the_summary_that_the_command_line_prints(tmp_path):
    run_dir_io.create(tmp_path, CFG)
    for rows in synthetic_chunks():
        run_dir_io.append_metrics(tmp_path, rows)
    assert health.of_run(tmp_path).summary()[0].startswith("learner 1 (viscous, seed 0) collapsed")


def test_a_network_collapsed_in_its_home_test_is_named_in_table2_claims_and_compare(tmp_path):
    # A committed evaluation with one network made to fail its home test: viscous seed 0 in viscous -> viscous.
    source = ROOT / "runs" / "heldout"
    (tmp_path / "eval").mkdir()
    for name in ("config.json", "metrics.jsonl.gz"):
        shutil.copy(source / name, tmp_path / name)
    for name in ("table2", "aftereffect", "impedance"):
        shutil.copy(source / "eval" / f"{name}.json", tmp_path / "eval" / f"{name}.json")
    path = tmp_path / "eval" / "table2.json"
    table = json.loads(path.read_text())
    for r in table["per_network"]:
        if (r["learning"], r["seed"], r["test"]) == ("viscous", 0, "viscous"):
            r.update(success=100, out=900, fail=40)
        if (r["learning"], r["seed"], r["test"]) == ("random", 1, "viscous"):
            r.update(success=100, out=900, fail=40)  # not its home test (random -> none): not a collapse
    path.write_text(json.dumps(table))
    result = judgements.redecide(tmp_path)
    recipe = result["recipes"][0]
    want = [{"learner": 8, "learning": "viscous", "seed": 0, "recipe": 0, "test": "viscous", "success": 100 / 1040}]
    assert recipe["collapsed"] == want
    assert {c["claim"]: bool(c["collapsed"]) for c in recipe["claims"]} == {
        1: True,
        2: False,
        3: True,
        4: False,
        5: False,
    }
    words = "viscous seed 0 (9.6%)"
    assert collapse.names(want) == words
    claims_md = (tmp_path / "eval" / "claims.md").read_text()
    assert claims_md.count(f"depends on collapsed networks: {words}") == 2
    assert "**Collapsed networks** (success below 50% in the test of their own learning condition" in claims_md
    assert "**Collapsed networks**" in (tmp_path / "eval" / "table2.md").read_text()
    row = compare.recipe_rows(tmp_path)[0]
    assert row["collapsed"] == words and f"| {words} |" in compare.markdown([row])
    # An evaluation written before collapses were named: compare reads them from its table2.json.
    older = json.loads((tmp_path / "eval" / "claims.json").read_text())
    for r in older["recipes"]:
        del r["collapsed"]
    (tmp_path / "eval" / "claims.json").write_text(json.dumps(older))
    assert compare.recipe_rows(tmp_path)[0]["collapsed"] == words
    assert compare.recipe_rows(source)[0]["collapsed"] == ""  # the committed run: none collapsed


def test_home_tests_are_the_own_condition_where_tested_else_the_null_field():
    tests = ("none", "viscous")
    assert [collapse.home_test(c, tests) for c in ("none", "viscous", "random", "random_nopast", "curl")] == [
        "none",
        "viscous",
        "none",
        "none",
        "none",
    ]
