"""Smoke test of the scripts in examples/: each runs in a subprocess with
``--quick`` (smaller data, fewer steps; every script says what it changes)
and must exit 0 and print its key result line. Outputs go to tmp_path."""
import os
import re
import subprocess
import sys

import pytest

EXAMPLES = os.path.join(os.path.dirname(os.path.dirname(
    os.path.abspath(__file__))), 'examples')

# script -> a regular expression for the line that carries its result
KEY_LINES = {
    'deltaconv.py': (r'max \|grad z - tangential e_z\| = \d\.\d+e[-+]\d+',
                     r'DeltaNet test accuracy: \d\.\d{3}'),
    'hsn.py': (r'HSN test accuracy: \d\.\d{3}',
               r'max relative change of the logits \d\.\de[-+]\d+'),
    'gravo_mg.py': (r'smoothing .* relative residual \d\.\de-\d+, relative '
                    r'difference to spsolve \d\.\de-\d+',
                    r'screened Poisson .* relative residual \d\.\de-\d+'),
    'svbrdf.py': (r'SVBRDF: roughness MAE \d\.\d{3}, base-colour RMSE '
                  r'\d\.\d{3}, Spearman\(roughness_std, roughness error\) '
                  r'[-+]\d\.\d\d',),
}


def test_every_example_is_covered():
    scripts = sorted(f for f in os.listdir(EXAMPLES) if f.endswith('.py'))
    assert scripts == sorted(KEY_LINES)


@pytest.mark.parametrize('script', sorted(KEY_LINES))
def test_example_runs(script, tmp_path):
    env = dict(os.environ)
    # One thread each: the smoke test checks that the script works, and on
    # a shared 2-core machine oversubscribed thread pools only slow it down.
    env.update(OMP_NUM_THREADS='1', NUMBA_NUM_THREADS='1',
               MKL_NUM_THREADS='1')
    run = subprocess.run(
        [sys.executable, os.path.join(EXAMPLES, script), '--quick', '--out',
         str(tmp_path)], cwd=tmp_path, env=env, capture_output=True,
        text=True, timeout=600)
    output = run.stdout + run.stderr
    assert run.returncode == 0, output[-4000:]
    for pattern in KEY_LINES[script]:
        assert re.search(pattern, run.stdout), \
            f"{script} did not print /{pattern}/:\n{run.stdout[-3000:]}"
    assert os.path.exists(tmp_path / 'results.json')
    # the figure the documentation's gallery shows
    assert os.path.getsize(tmp_path / 'figure.png') > 0
    # nothing is written outside --out (the source tree stays clean)
    assert not os.path.exists(os.path.join(EXAMPLES, 'runs'))
