r"""Geometric multigrid hierarchies (Gravo MG): sampling of coarse points,
graph Voronoi cells and the prolongation operators between levels."""
from .voronoi import graph_voronoi
from .gravo import GravoLevel, gravo_level, gravo_hierarchy

__all__ = ['graph_voronoi', 'GravoLevel', 'gravo_level', 'gravo_hierarchy']
