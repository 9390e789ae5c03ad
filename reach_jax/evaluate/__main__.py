"""`python -m reach_jax.evaluate`: the evaluation command line (`reach_jax.evaluate.cli`)."""

import sys

from reach_jax.evaluate import cli

sys.exit(cli.main())
