"""What the gallery's examples are run with when the site is built."""
import os

#: where the examples write their outputs during a build
GALLERY_OUT = os.path.join(os.path.dirname(os.path.abspath(__file__)),
                           '_build', 'gallery_runs')


#: more epochs than --quick's for the examples that train, so that their
#: learning curves are curves, not one or two points (seconds each)
EPOCHS = {'hsn': 8, 'deltaconv': 6}


def example_arguments(gallery_conf, script_vars):
    """Every example runs with ``--quick`` (the networks with
    :data:`EPOCHS`) and writes under the build."""
    name = os.path.splitext(os.path.basename(script_vars['src_file']))[0]
    epochs = ['--epochs', str(EPOCHS[name])] if name in EPOCHS else []
    return ['--quick', *epochs, '--out', os.path.join(GALLERY_OUT, name)]
