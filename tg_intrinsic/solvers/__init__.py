"""tg_intrinsic.solvers (filled in by later issues)."""
