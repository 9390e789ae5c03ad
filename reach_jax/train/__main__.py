"""`python -m reach_jax.train`: the training command line (`reach_jax.train.cli`)."""

import sys

from reach_jax.train import cli

sys.exit(cli.main())
