"""reach_jax: Shibata & Ito's force-load reaching experiment (ICONIP 2002), vectorized over learners in JAX.

The package is layered; each folder imports only the ones below it:

- `evaluate`: reads trained networks: Table 2, Fig. 4-5, after-effect, impedance, adaptation, the claims; its CLI.
- `train`: the loop over compiled chunks, its sinks (metrics, checkpoints, progress) and its CLI.
- `store`: run directories, their metrics log, checkpoints, durable file writes.
- `engine`: a learner's state, its random stream, the agent step, compiled chunks, batches, devices.
- `agent`: the network, the TS actor-critic learner, exploration.
- `env`: the trial (reset, step, auto-reset), task, curriculum, protocols, the per-trial log.
- `physics`: the arm (eq. 4-5), force fields, the visual sensor, the input encoding.
- `config`: the schema of every constant, shipped tables, the paper's numbers, loading and migration.
- `errors`: one-line user errors and the exit codes; `testing`: the NumPy oracle, for tests and benchmarks.

`from reach_jax import config, train, evaluate` is most of a user's import; `engine.distribute.setup_backend` picks
the devices before JAX starts, and `store.run_dir` reads a run's files.
"""
