"""The README's and the documentation pages' examples run as written: every
Python block of a page, in order, in one namespace per page (placeholder
folders swapped for generated meshes), and every `tg-intrinsic` command
line of their shell blocks parses."""
import glob
import os
import re
import shlex

import pytest

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), '..')
README = os.path.join(ROOT, 'README.md')
# the pages whose Python blocks run, in the site's order
PAGES = [README] + [os.path.join(ROOT, 'docs', page) for page in (
    'getting_started.md', 'methods/deltaconv.md', 'methods/hsn.md',
    'methods/gravo_mg.md', 'methods/svbrdf.md', 'pyg_integration.md')]


def blocks(path, language):
    text = open(path, encoding='utf-8').read()
    return re.findall(rf'```{language}\n(.*?)```', text, flags=re.S)


def command_lines():
    for path in PAGES + glob.glob(os.path.join(ROOT, 'docs', '*.md')):
        for block in blocks(path, 'bash'):
            for line in block.replace('\\\n', ' ').split('\n'):
                line = line.split('#', 1)[0].strip()
                if line.startswith('tg-intrinsic '):
                    yield line


def make_mesh_folder(root):
    import trimesh
    for name, scale in (('ball', (1, 1, 1)), ('cigar', (3, 1, 1))):
        folder = root / name / 'train'
        folder.mkdir(parents=True)
        mesh = trimesh.creation.icosphere(1)
        mesh.apply_scale(scale)
        mesh.export(folder / f'{name}.off')


def test_the_pages_have_what_this_test_reads():
    assert all(blocks(page, 'python') for page in PAGES)
    # every page with Python in it is run
    for path in glob.glob(os.path.join(ROOT, 'docs', '**', '*.md'),
                          recursive=True):
        if blocks(path, 'python'):
            assert os.path.abspath(path) in map(os.path.abspath, PAGES)
    assert set(PROMISES) <= {os.path.relpath(page, ROOT) for page in PAGES}
    commands = {line.split()[1] for line in command_lines()}
    assert {'info', 'solve', 'precompute', 'svbrdf', 'train'} <= commands


def test_every_command_line_parses():
    from tg_intrinsic.cli import build_parser
    parser = build_parser()
    for line in command_lines():
        args = parser.parse_args(shlex.split(line)[1:])
        assert args.command == line.split()[1]


def run_blocks(path, tmp_path):
    """Runs the Python blocks of ``path`` in order; returns the namespace."""
    namespace = {'__name__': '__page__'}
    name = os.path.relpath(path, ROOT)
    for index, code in enumerate(blocks(path, 'python')):
        code = code.replace('path/to/ModelNet10', str(tmp_path / 'meshes'))
        try:
            exec(compile(code, f'{name} python block {index + 1}', 'exec'),
                 namespace)
        except Exception as error:  # noqa: BLE001 - named in the failure
            pytest.fail(f'{name} python block {index + 1} failed: '
                        f'{type(error).__name__}: {error}')
    return namespace


# what a page's blocks promise to leave behind, by page
PROMISES = {
    'README.md': lambda ns, tmp: ns['logits'].shape[-1]
    == ns['clouds'].num_classes,
    'docs/methods/hsn.md': lambda ns, tmp: ns['logits'].shape[-1]
    == ns['meshes'].num_classes,
    'docs/methods/gravo_mg.md': lambda ns, tmp: tuple(ns['X'].shape) == (
        ns['n'], 16) and ns['fine'].shape == ns['surface'].pos.shape,
    'docs/methods/svbrdf.md': lambda ns, tmp: (
        tmp / 'runs' / 'svbrdf' / 'maps.npz').exists(),
    'docs/pyg_integration.md': lambda ns, tmp: (
        ns['sizes'] == [100, 100]
        and ns['edge_importance'].shape == (ns['data'].num_edges, )
        and ns['edge_importance'].std() > 0
        and ns['logits'].shape == (8, 2)
        and ns['diffusion'].diffusion_time.grad is not None),
}


@pytest.mark.parametrize('page', PAGES,
                         ids=[os.path.relpath(p, ROOT) for p in PAGES])
def test_the_python_blocks_run_in_order(page, tmp_path, monkeypatch):
    make_mesh_folder(tmp_path / 'meshes')
    monkeypatch.chdir(tmp_path)
    namespace = run_blocks(page, tmp_path)
    promise = PROMISES.get(os.path.relpath(page, ROOT))
    assert promise is None or promise(namespace, tmp_path)
