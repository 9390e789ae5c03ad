"""`python -m reach_jax.evaluate`: the evaluation command line (`reach_jax.cli`)."""

import sys

from reach_jax import cli

sys.exit(cli.evaluate_main())
