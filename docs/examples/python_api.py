"""Train a tiny run from Python, evaluate it and load its networks (the Python API page shows this file).

Run it as `python docs/examples/python_api.py [OUT]` (default OUT: runs/api); tests/test_readme.py runs it too.
"""

import sys

from reach_jax import config, evaluate, train
from reach_jax.engine import distribute
from reach_jax.store import run_dir

distribute.setup_backend()  # before JAX's first computation: the CLIs' compiler flags and one device per core

# A config from a few fields: each is checked as config.json is, and the rest take today's defaults. The paper's
# field trains in the frame that today's evaluation judges first ("viscous_mirror", config.Config().eval.frames).
cfg = config.from_partial({"train": {"trials": 20, "seeds": 1, "conditions": ["none", "viscous_mirror"]}})

out = sys.argv[1] if len(sys.argv) > 1 else "runs/api"
path = train.run(cfg, out, progress=False)  # one compiled batch of learners; returns the run directory
results = evaluate.evaluate(path)  # writes OUT/eval/ and returns the same results as a dict

table2 = results["table2"]
for row in table2["rows"]:  # Table 2's cells: success, out and fail counts over the lattice pairs
    share = row["success"] / (row["networks"] * table2["pairs_per_network"])
    print(f"{row['learning']} -> {row['test']}: success {share:.1%}")
print("claim 1:", results["claims"]["recipes"][0]["claims"][0]["verdict"])

params, learners = run_dir.load_params(path)  # flax parameters, learner axis first
print("learners (condition, seed):", learners)
