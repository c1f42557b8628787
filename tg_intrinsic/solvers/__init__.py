"""Solvers for linear systems on surfaces."""
from .gravo_mg import ConvergenceWarning, GravoMG, SolveInfo
from .systems import poisson, smooth, stiffness_and_mass

__all__ = ['GravoMG', 'SolveInfo', 'ConvergenceWarning', 'smooth', 'poisson', 'stiffness_and_mass']
