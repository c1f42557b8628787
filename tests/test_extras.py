"""The extras' one list: setup.py runs tg_intrinsic/extras.py without
importing the package (which needs torch), and pip's metadata of the
installed package holds the same extras."""
import ast
import importlib.metadata
import os

from tg_intrinsic.extras import EXTRAS

PATH = os.path.join(os.path.dirname(os.path.abspath(__file__)), '..',
                    'tg_intrinsic', 'extras.py')


def test_the_file_runs_alone():
    tree = ast.parse(open(PATH, encoding='utf-8').read())
    assert not [node for node in ast.walk(tree)
                if isinstance(node, (ast.Import, ast.ImportFrom))]


def test_every_extra_has_requirements_and_a_reason():
    for name, (requirements, needed_by) in EXTRAS.items():
        assert requirements and all(isinstance(r, str) for r in requirements)
        assert len(needed_by.split()) >= 3, name


def test_the_installed_package_provides_every_extra():
    provided = importlib.metadata.metadata('tg_intrinsic').get_all(
        'Provides-Extra')
    assert set(provided) == set(EXTRAS)
    assert {'textures', 'h5', 'digits', 'docs', 'heat', 'exr', 'mitsuba',
            'scatter', 'benchmarks', 'test'} <= set(EXTRAS)
