"""The engine layer: a learner's whole state, its random stream, one agent step, compiled chunks of steps, batches of
learners and their spread over devices and processes."""

from reach_jax.engine import batch, chunk, distribute, learner_state, random_stream, rollout

__all__ = ["batch", "chunk", "distribute", "learner_state", "random_stream", "rollout"]
