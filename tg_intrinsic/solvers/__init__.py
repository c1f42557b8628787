"""Solvers for linear systems on surfaces, and batched Levenberg-Marquardt
for many small fits, independent or coupled by a total variation."""
from .gravo_mg import ConvergenceWarning, GravoMG, SolveInfo
from .levenberg_marquardt import (LMInfo, levenberg_marquardt,
                                  levenberg_marquardt_tv)
from .systems import (conformal_flow, diffuse, poisson, smooth,
                      stiffness_and_mass)

__all__ = ['GravoMG', 'SolveInfo', 'ConvergenceWarning', 'smooth',
           'poisson', 'diffuse', 'conformal_flow', 'stiffness_and_mass',
           'levenberg_marquardt', 'levenberg_marquardt_tv', 'LMInfo']
