"""What the tests and benchmarks check reach_jax against; not used by training or evaluation."""
