"""The store layer: run directories (one reader, one writer, held by a lock), their metrics log, checkpoints and
durable file writes."""

from reach_jax.store import checkpoint, files, metrics_log, run_dir, run_lock

__all__ = ["checkpoint", "files", "metrics_log", "run_dir", "run_lock"]
