"""tg_intrinsic.nn (filled in by later issues)."""
