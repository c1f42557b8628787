"""The package layout: old module paths keep working, no module reaches
into another file's private names, and the tests mirror the package file by
file."""
import ast
import importlib
import os
import sys

import pytest

import tg_intrinsic
from tg_intrinsic import geometry
from tg_intrinsic.geometry import MOVED_MODULES

PACKAGE = os.path.dirname(tg_intrinsic.__file__)
TESTS = os.path.dirname(__file__)


@pytest.mark.parametrize('old', sorted(k for k, v in MOVED_MODULES.items()
                                       if isinstance(v, str)))
def test_moved_modules_import_from_their_old_path(old):
    name = f'tg_intrinsic.geometry.{old}'
    sys.modules.pop(name, None)
    with pytest.warns(DeprecationWarning, match='moved to'):
        legacy = importlib.import_module(name)
    new = importlib.import_module(
        f'tg_intrinsic.geometry.{MOVED_MODULES[old]}')
    assert legacy is new
    for public in getattr(new, '__all__', []):
        assert getattr(legacy, public) is getattr(new, public)


def test_the_split_renderer_keeps_its_names():
    sys.modules.pop('tg_intrinsic.geometry.render', None)
    with pytest.warns(DeprecationWarning, match='was split into'):
        from tg_intrinsic.geometry.render import (camera_centers,
                                                  point_visibility,
                                                  rasterize, render_images,
                                                  render_radiance)
    from tg_intrinsic.datasets.capture import render_images as images
    from tg_intrinsic.geometry.appearance import (
        camera_centers as centres, point_visibility as visibility,
        rasterize as raster, render_radiance as radiance)
    assert (camera_centers, point_visibility, rasterize, render_images,
            render_radiance) == (centres, visibility, raster, images,
                                 radiance)


def test_unknown_old_names_still_fail():
    with pytest.raises(ModuleNotFoundError):
        importlib.import_module('tg_intrinsic.geometry.no_such_module')


@pytest.mark.parametrize('package', ['pointcloud', 'geodesics', 'multigrid',
                                     'appearance'])
def test_domain_packages_export_what_they_list(package):
    module = importlib.import_module(f'tg_intrinsic.geometry.{package}')
    assert module.__all__
    for name in module.__all__:
        assert getattr(module, name) is not None
    for name in geometry.__all__:
        assert getattr(geometry, name) is not None


def imports_of(path):
    """(line, absolute module, imported names) of every import in a file of
    the package."""
    module = os.path.relpath(path, os.path.dirname(PACKAGE))[:-3]
    module = module.replace(os.sep, '.')
    package = module.rsplit('.', 1)[0]
    if module.endswith('.__init__'):
        package = module[:-len('.__init__')]
    for node in ast.walk(ast.parse(open(path).read())):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                parts = package.split('.')
                parts = parts[:len(parts) - node.level + 1]
                target = '.'.join(parts + ([node.module] if node.module
                                           else []))
            else:
                target = node.module or ''
            yield node.lineno, package, target, [a.name for a in node.names]
        elif isinstance(node, ast.Import):
            for alias in node.names:
                yield node.lineno, package, alias.name, []


def private(name):
    return name.startswith('_') and not name.startswith('__')


def test_no_private_name_is_imported_across_files():
    found = []
    for root, _, files in os.walk(PACKAGE):
        for file in files:
            if not file.endswith('.py'):
                continue
            path = os.path.join(root, file)
            for line, package, target, names in imports_of(path):
                if not target.startswith('tg_intrinsic'):
                    continue
                where = f'{os.path.relpath(path, PACKAGE)}:{line}'
                found += [f'{where} imports {name} from {target}'
                          for name in names if private(name)]
                parts = target.split('.')
                for i, part in enumerate(parts):
                    # a private module belongs to its own package only
                    if private(part) and package != '.'.join(parts[:i]):
                        found.append(f'{where} imports the private module '
                                     f'{target}')
    assert not found, '\n'.join(found)


def test_every_public_module_has_its_test_module():
    # tg_intrinsic/a/b.py is tested in tests/a/test_b.py
    missing = []
    for root, _, files in os.walk(PACKAGE):
        for file in files:
            if not file.endswith('.py') or file.startswith('_'):
                continue
            folder = os.path.relpath(root, PACKAGE)
            test = os.path.normpath(os.path.join(TESTS, folder,
                                                 f'test_{file}'))
            if not os.path.isfile(test):
                module = os.path.normpath(os.path.join(folder, file))
                missing.append(f'{module}: {os.path.relpath(test, TESTS)}')
    assert not missing, 'modules without tests:\n' + '\n'.join(missing)
