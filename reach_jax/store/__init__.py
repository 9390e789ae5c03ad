"""The store layer: run directories (one reader, one writer), checkpoints and durable file writes."""

from reach_jax.store import checkpoint, files, run_dir

__all__ = ["checkpoint", "files", "run_dir"]
