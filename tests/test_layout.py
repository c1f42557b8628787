"""The package layout: old module paths keep working, no module reaches
into another file's private names, and the tests mirror the package file by
file."""
import ast
import glob
import importlib
import importlib.util
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
    # the module keeps its own identity, so its relative imports resolve
    assert new.__spec__.name == new.__name__
    assert new.__spec__.parent == new.__package__
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


# ../shared/DESIGN.md's order: a module imports only from its own floor or
# below (geometry <- transforms <- nn/pool/solvers <- io <- datasets,
# training, cli)
FLOORS = {'errors': 0, 'extras': 0, 'utils': 0, 'devices': 0, 'geometry': 0,
          'parallel': 1, 'surface_attributes': 1, 'data': 1,
          'transforms': 2, 'nn': 3, 'pool': 3, 'solvers': 3, 'io': 4,
          'datasets': 5, 'protocols': 5, 'distributed': 5, 'train': 5,
          'training': 5, 'cli': 6, '__main__': 7}


def package_imports():
    """``{module: {imported tg_intrinsic modules}}`` of every module of
    the package, imports inside functions included."""
    root = os.path.dirname(tg_intrinsic.__file__)
    found = {}
    for folder, _, files in os.walk(root):
        for name in files:
            if not name.endswith('.py'):
                continue
            path = os.path.join(folder, name)
            module = 'tg_intrinsic.' + os.path.relpath(
                path, root)[:-3].replace(os.sep, '.')
            module = module.removesuffix('.__init__')
            package = module if name == '__init__.py' else \
                module.rsplit('.', 1)[0]
            targets = set()
            for node in ast.walk(ast.parse(open(path).read())):
                if isinstance(node, ast.ImportFrom):
                    base = node.module or ''
                    if node.level:
                        parts = package.split('.')
                        parts = parts[:len(parts) - node.level + 1]
                        base = '.'.join(parts + ([base] if base else []))
                    # a name may be a module of the package or an
                    # attribute of ``base``
                    names = [f'{base}.{a.name}' if os.path.exists(
                        module_path(f'{base}.{a.name}')) else base
                        for a in node.names]
                    targets.update(n for n in names
                                   if n.startswith('tg_intrinsic'))
                elif isinstance(node, ast.Import):
                    targets.update(a.name for a in node.names
                                   if a.name.startswith('tg_intrinsic'))
            found[module] = targets
    return found


def module_path(module: str) -> str:
    """The file of a module of the package (a package's ``__init__``)."""
    path = os.path.join(os.path.dirname(PACKAGE),
                        *module.split('.'))
    return path + '.py' if not os.path.isdir(path) else path


def floor_of(module: str):
    parts = module.split('.')
    return FLOORS.get(parts[1]) if len(parts) > 1 else None


def test_imports_only_run_down_the_layers():
    upward = [f'{module} -> {target}'
              for module, targets in package_imports().items()
              for target in targets
              if floor_of(target) is not None and floor_of(module) is not None
              and floor_of(target) > floor_of(module)]
    assert not upward, upward
    unknown = {module.split('.')[1] for module in package_imports()
               if '.' in module and floor_of(module) is None}
    assert not unknown, f'give these a floor in FLOORS: {unknown}'


def test_no_two_modules_import_each_other():
    imports = package_imports()
    both = sorted({tuple(sorted((a, b))) for a, targets in imports.items()
                   for b in targets if a != b and a in imports.get(b, ())})
    assert not both, both


SCRIPTS = sorted(
    os.path.relpath(path, os.path.dirname(PACKAGE))
    for pattern in ('benchmarks/*.py', 'benchmarks/*/*.py', 'examples/*.py')
    for path in glob.glob(os.path.join(os.path.dirname(PACKAGE), pattern)))


def test_scripts_use_names_the_package_has():
    """The benchmarks and examples, which no test runs in full, name only
    what the package has: ``from tg_intrinsic.x import y`` and
    ``module.name`` of a module imported so (compile_precision.py kept
    calling ``tg_intrinsic.train.autocast`` after it moved to
    ``tg_intrinsic.devices``)."""
    missing = []
    for script in SCRIPTS:
        path = os.path.join(os.path.dirname(PACKAGE), script)
        tree = ast.parse(open(path).read())
        modules = {}
        for node in ast.walk(tree):
            if not isinstance(node, ast.ImportFrom) or node.level or \
                    not (node.module or '').startswith('tg_intrinsic'):
                continue
            parent = importlib.import_module(node.module)
            for alias in node.names:
                if hasattr(parent, '__path__') and importlib.util.find_spec(
                        f'{node.module}.{alias.name}') is not None:
                    modules[alias.asname or alias.name] = \
                        importlib.import_module(f'{node.module}.{alias.name}')
                elif not hasattr(parent, alias.name):
                    missing.append(f'{script}:{node.lineno} imports '
                                   f'{alias.name} from {node.module}')
        missing += [f'{script}:{node.lineno} uses {node.value.id}.{node.attr}'
                    for node in ast.walk(tree)
                    if isinstance(node, ast.Attribute)
                    and isinstance(node.value, ast.Name)
                    and node.value.id in modules
                    and not hasattr(modules[node.value.id], node.attr)]
    assert SCRIPTS and not missing, '\n'.join(missing)
