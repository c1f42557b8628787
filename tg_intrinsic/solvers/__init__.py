"""Solvers for linear systems on surfaces."""
from .gravo_mg import GravoMG, SolveInfo

__all__ = ['GravoMG', 'SolveInfo']
