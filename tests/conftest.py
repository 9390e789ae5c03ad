"""Test-session setup: the CPU compiler options that the command lines set, before JAX starts."""

from reach_jax import distribute


def pytest_configure(config):
    """Give the test process (and the subprocesses it starts, which inherit XLA_FLAGS) the CLIs' backend flags."""
    distribute.add_xla_flags()
