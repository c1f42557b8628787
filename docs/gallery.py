"""What the gallery's examples are run with when the site is built."""
import os

#: where the examples write their outputs during a build
GALLERY_OUT = os.path.join(os.path.dirname(os.path.abspath(__file__)),
                           '_build', 'gallery_runs')


def example_arguments(gallery_conf, script_vars):
    """Every example runs with ``--quick`` and writes under the build."""
    name = os.path.splitext(os.path.basename(script_vars['src_file']))[0]
    return ['--quick', '--out', os.path.join(GALLERY_OUT, name)]
