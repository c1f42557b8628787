"""tg_intrinsic.pool (filled in by later issues)."""
