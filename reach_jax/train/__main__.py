"""`python -m reach_jax.train`: the training command line (`reach_jax.cli`)."""

import sys

from reach_jax import cli

sys.exit(cli.train_main())
