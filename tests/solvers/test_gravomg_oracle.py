"""The original Gravo MG (PyPI gravomg 0.0.4, in its own numpy < 2
environment: ``make gravomg-env``, or TG_GRAVOMG_PYTHON pointing to a
Python that has it) on the same system: level sizes and cycle counts.
Skipped where that environment is absent."""
import os
import subprocess

import numpy as np
import pytest
import trimesh

from tg_intrinsic.solvers import GravoMG

from tests.solvers.test_gravo_mg import face_edges, mesh_system

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
ORACLE = os.path.join(ROOT, 'benchmarks', 'oracles', 'gravomg_oracle.py')
PYTHON = os.environ.get('TG_GRAVOMG_PYTHON',
                        os.path.join(ROOT, '.gravomg-env', 'bin', 'python'))

pytestmark = pytest.mark.skipif(
    not os.path.exists(PYTHON),
    reason='no Python with gravomg 0.0.4 (make gravomg-env)')


def run_original(tmp_path, pos, face, A, m, b, tol, lower_bound):
    source, target = tmp_path / 'in.npz', tmp_path / 'out.npz'
    np.savez(source, pos=pos, face=face, data=A.data, indices=A.indices,
             indptr=A.indptr, m=m, b=b, tol=tol, lower_bound=lower_bound)
    subprocess.run([PYTHON, ORACLE, str(source), str(target)], check=True,
                   env={k: v for k, v in os.environ.items()
                        if k != 'PYTHONPATH'})
    return np.load(target)


def test_level_sizes_and_cycles_against_the_original(tmp_path):
    mesh = trimesh.creation.icosphere(5)
    pos = np.asarray(mesh.vertices)
    face = np.asarray(mesh.faces, dtype=np.int64)
    A, m = mesh_system(pos, face)
    b = m * np.random.default_rng(1).normal(size=pos.shape[0])
    theirs = run_original(tmp_path, pos, face, A, m, b, 1e-8, 100)
    solver = GravoMG.from_points(pos, face_edges(face), lower_bound=100)
    ours = [pos.shape[0]] + [P.shape[1] for P in solver.prolongations]
    assert len(ours) == len(theirs['sizes'])
    assert np.all(np.abs(np.array(ours) / theirs['sizes'] - 1) < 0.1)
    x = solver.solve(A, b, tol=1e-8)
    assert np.linalg.norm(x - theirs['x']) / np.linalg.norm(x) < 1e-6
    # Forward Gauss-Seidel before and after, as the original: no more
    # cycles than it needs (7 here; backward post-smoothing took 9).
    assert solver.info.iterations <= int(theirs['iterations'])
