"""The store layer: run directories (one reader, one writer, held by a lock), checkpoints and durable file writes."""

from reach_jax.store import checkpoint, files, run_dir, run_lock

__all__ = ["checkpoint", "files", "run_dir", "run_lock"]
