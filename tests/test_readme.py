"""The README's examples run as written: every Python block, in order, in
one namespace (its placeholder folder swapped for generated meshes), and
every `tg-intrinsic` command line of its shell blocks parses."""
import os
import re
import shlex

import pytest

README = os.path.join(os.path.dirname(__file__), '..', 'README.md')


def blocks(language):
    text = open(README, encoding='utf-8').read()
    return re.findall(rf'```{language}\n(.*?)```', text, flags=re.S)


def command_lines():
    for block in blocks('bash'):
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


def test_the_readme_has_what_this_test_reads():
    assert len(blocks('python')) >= 5
    commands = {line.split()[1] for line in command_lines()}
    assert {'info', 'solve', 'precompute', 'svbrdf', 'train'} <= commands


def test_every_command_line_of_the_readme_parses():
    from tg_intrinsic.cli import build_parser
    parser = build_parser()
    for line in command_lines():
        args = parser.parse_args(shlex.split(line)[1:])
        assert args.command == line.split()[1]


def test_the_python_blocks_run_in_order(tmp_path, monkeypatch):
    make_mesh_folder(tmp_path / 'meshes')
    monkeypatch.chdir(tmp_path)
    namespace = {'__name__': '__readme__'}
    for index, code in enumerate(blocks('python')):
        code = code.replace('path/to/ModelNet10', str(tmp_path / 'meshes'))
        try:
            exec(compile(code, f'README.md python block {index + 1}',
                         'exec'), namespace)
        except Exception as error:  # noqa: BLE001 - named in the failure
            pytest.fail(f'README python block {index + 1} failed: '
                        f'{type(error).__name__}: {error}')
    # what the blocks promise to leave behind
    assert (tmp_path / 'runs' / 'svbrdf' / 'maps.npz').exists()
    assert tuple(namespace['X'].shape) == (namespace['n'], 16)
    assert namespace['fine'].shape == namespace['surface'].pos.shape
    assert namespace['logits'].shape[-1] == namespace['meshes'].num_classes
