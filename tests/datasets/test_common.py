"""The datasets' shared helpers: the processed folder per pre-processing,
option checks that name the option and its choices, file-name text of
parameters, per-shape random streams, atomic caches, the folder scans,
and FolderDataset (a tiny reader of number files here) with its
manifest, caching and errors."""
import os
import os.path as osp
import re

import numpy as np
import pytest
import torch
from torch_geometric.data import Data

from tg_intrinsic.data import IntrinsicData
from tg_intrinsic.datasets.common import (PROCESSED, FolderDataset,
                                          GeneratedDataset, check_option,
                                          check_split, check_task,
                                          class_folders, file_manifest,
                                          find_label_file, fmt, list_files,
                                          processed_folder,
                                          processing_suffix, save_atomic,
                                          shape_rng)
from tg_intrinsic.utils import TEMPORARY_PREFIX


def make_identity():
    """A new function object each call, with the same text."""
    def identity(data):
        return data
    return identity


class Scale:
    def __init__(self, factor):
        self.factor = factor

    def __call__(self, data):
        data.pos = data.pos * self.factor
        return data

    def __repr__(self):
        return f'Scale({self.factor})'


# --- the processed folder per pre-processing ------------------------------


def test_processing_suffix():
    assert processing_suffix(None, None) == ''
    suffix = processing_suffix(Scale(2), None)
    assert re.fullmatch(r'_[0-9a-f]{10}', suffix)
    assert processing_suffix(Scale(2), None) == suffix  # by text
    assert processing_suffix(Scale(3), None) != suffix
    assert processing_suffix(None, Scale(2)) != suffix  # filter != transform
    # functions print with their address; it is dropped so that the same
    # function hashes the same in every run
    first, second = make_identity(), make_identity()
    assert first is not second and repr(first) != repr(second)
    assert processing_suffix(first, None) == processing_suffix(second, None)
    assert processed_folder('r', None, None) == osp.join('r', PROCESSED)
    assert processed_folder('r', Scale(2), None) == \
        osp.join('r', PROCESSED + suffix)


# --- option checks ---------------------------------------------------------


def test_option_checks_name_the_option_and_the_choices():
    assert check_option('b', 'mode', ('a', 'b')) == 'b'
    with pytest.raises(ValueError) as info:
        check_option('c', 'mode', ['a', 'b'])
    assert str(info.value) == "'mode' must be one of ('a', 'b'), got 'c'"
    assert check_split('test') == 'test'
    with pytest.raises(ValueError, match=r"'split' must be one of \('train', "
                       r"'test'\), got 'val'"):
        check_split('val')
    assert check_split('val', ('train', 'val')) == 'val'


def test_check_task():
    assert check_task('segmentation', num_classes=(5, None)) == \
        'segmentation'
    assert check_task('classification', num_classes=(None, None),
                      label_offset=(0, 0)) == 'classification'
    with pytest.raises(ValueError) as info:
        check_task('classification', num_classes=(5, None),
                   label_offset=(1, 0), label_kind=('auto', 'auto'))
    assert str(info.value).startswith(
        "'num_classes', 'label_offset' apply to task='segmentation' only; "
        "classification takes its classes from the folder names")
    with pytest.raises(ValueError, match=r"'task' must be one of "
                       r"\('classification', 'segmentation'\), got "
                       r"'regression'"):
        check_task('regression')


@pytest.mark.parametrize('value,text', [
    (True, '1'), (False, '0'), (np.bool_(True), '1'), (0.5, '0.5'),
    (1.0, '1'), (1e-5, '0.00001'), (np.float32(0.25), '0.25'), (3, '3'),
    ((500, 2000), '500-2000'), ([0.8, 1.25, True], '0.8-1.25-1'),
    ('PB_T50_RS', 'PB_T50_RS')])
def test_fmt_is_short_file_name_text(value, text):
    assert fmt(value) == text
    assert not set(fmt(value)) & set('/\\ :*?"<>|')


def test_shape_rng_streams_are_per_shape():
    def draw(*args):
        return shape_rng(*args).random(4)
    assert np.array_equal(draw(0, 3, 1), draw(0, 3, 1))
    assert not np.array_equal(draw(0, 3, 1), draw(0, 3, 2))
    assert not np.array_equal(draw(0, 3, 1), draw(1, 3, 1))
    assert not np.array_equal(draw(0, 3, 1), draw(0, 1, 3))
    # the stream of a shape does not depend on the draws of the others
    rng = shape_rng(0, 0, 0)
    rng.random(1000)
    assert np.array_equal(draw(0, 0, 1), shape_rng(0, 0, 1).random(4))
    assert np.array_equal(draw(np.int64(7), 2), draw(7, 2))


# --- atomic caches and generated data sets ---------------------------------


def test_save_atomic_writes_a_collated_cache(tmp_path):
    data = [IntrinsicData(pos=torch.full((n, 3), float(n)), y=torch.tensor(
        [n])) for n in (2, 3)]
    path = tmp_path / 'cache.pt'
    save_atomic(GeneratedDataset, data, str(path))
    assert os.listdir(tmp_path) == ['cache.pt']
    stored, slices, cls = torch.load(path, weights_only=False)
    assert cls is IntrinsicData
    assert slices['pos'].tolist() == [0, 2, 5]
    assert torch.equal(stored['pos'], torch.cat([d.pos for d in data]))
    assert stored['y'].tolist() == [2, 3]


class Counting(GeneratedDataset):
    """Three generated examples; counts its process() calls."""
    calls = 0

    @property
    def processed_file_names(self):
        return ['data.pt']

    def process(self):
        type(self).calls += 1
        data = [Data(pos=torch.tensor([[float(i), 0.0, 0.0]]))
                for i in range(3)]
        if self.pre_transform is not None:
            data = [self.pre_transform(d) for d in data]
        save_atomic(type(self), data, self.processed_paths[0])

    def __init__(self, root, pre_transform=None):
        super().__init__(root, None, pre_transform, None, log=False)
        self.load(self.processed_paths[0])


def test_a_generated_dataset_is_made_once_per_pre_processing(tmp_path):
    Counting.calls = 0
    plain = Counting(str(tmp_path))
    assert [float(d.pos[0, 0]) for d in plain] == [0.0, 1.0, 2.0]
    assert plain.raw_file_names == [] and Counting.calls == 1
    assert plain.processed_dir == osp.join(str(tmp_path), 'processed')
    Counting(str(tmp_path))
    assert Counting.calls == 1  # cached
    scaled = Counting(str(tmp_path), pre_transform=Scale(10))
    assert Counting.calls == 2 and float(scaled[2].pos[0, 0]) == 20.0
    assert scaled.processed_dir == osp.join(
        str(tmp_path), 'processed' + processing_suffix(Scale(10), None))
    assert float(Counting(str(tmp_path))[2].pos[0, 0]) == 2.0
    assert Counting.calls == 2


# --- folder scans -----------------------------------------------------------


def test_list_files_and_class_folders(tmp_path):
    assert list_files(str(tmp_path / 'missing'), ('.obj', )) == []
    for name in ('b.OBJ', 'a.obj', 'c.off', 'notes.txt'):
        (tmp_path / name).write_text('')
    (tmp_path / 'folder.obj').mkdir()  # a folder, not a file
    assert list_files(str(tmp_path), ('.obj', '.off')) == [
        str(tmp_path / n) for n in ('a.obj', 'b.OBJ', 'c.off')]
    for folder in ('chair/train', 'bed/test', 'lamp/val', '.hidden/train',
                   PROCESSED + '/train', PROCESSED + '_ab12/train'):
        (tmp_path / folder).mkdir(parents=True)
    (tmp_path / 'desk').write_text('a file')
    assert class_folders(str(tmp_path), ('train', 'test')) == ['bed',
                                                               'chair']
    assert class_folders(str(tmp_path), ('val', )) == ['lamp']


def test_find_label_file(tmp_path):
    beside, labels = tmp_path / 'train', tmp_path / 'labels'
    beside.mkdir()
    labels.mkdir()

    def find(stem):
        return find_label_file(stem, str(beside), ('.txt', '.seg'),
                               [str(labels), str(tmp_path / 'none')],
                               ('.eseg', '.txt'))

    assert find('a') is None
    (beside / 'a.seg').write_text('0')
    assert find('a') == str(beside / 'a.seg')
    (labels / 'b.eseg').write_text('1')
    assert find('b') == str(labels / 'b.eseg')
    (labels / 'a.txt').write_text('0')
    with pytest.raises(ValueError) as info:
        find('a')
    message = str(info.value)
    assert message.startswith("several label files for 'a': ")
    assert str(beside / 'a.seg') in message and str(labels / 'a.txt') in \
        message and message.endswith('keep one of them')


def test_file_manifest(tmp_path):
    (tmp_path / 'sub').mkdir()
    (tmp_path / 'sub' / 'a.txt').write_text('12345')
    (tmp_path / 'b.txt').write_text('1')
    paths = [str(tmp_path / 'sub' / 'a.txt'), str(tmp_path / 'b.txt')]
    manifest = file_manifest(str(tmp_path), paths)
    assert sorted(manifest) == ['b.txt', osp.join('sub', 'a.txt')]
    size, mtime = manifest[osp.join('sub', 'a.txt')]
    assert size == 5
    assert mtime == os.stat(tmp_path / 'sub' / 'a.txt').st_mtime_ns
    os.utime(tmp_path / 'b.txt', ns=(0, 10 ** 9))
    assert file_manifest(str(tmp_path), paths)['b.txt'] == [1, 10 ** 9]


# --- FolderDataset -----------------------------------------------------------


class Numbers(FolderDataset):
    """<class>/<split>/*.num files, each holding one number."""
    LAYOUT = '<class>/<train|test>/*.num'
    reads = 0

    def __init__(self, root, split='train', pre_transform=None,
                 pre_filter=None, force_reload=False):
        super().__init__(root, split, None, pre_transform, pre_filter,
                         False, force_reload)

    @property
    def cache_name(self):
        return f'numbers_{self.split}'

    def scan(self):
        self.classes, self.items = self.class_items(('.num', ))
        return [path for path, _ in self.items]

    def read(self):
        type(self).reads += 1
        data = [IntrinsicData(x=torch.tensor([[float(open(p).read())]]),
                              y=torch.tensor([c]))
                for p, c in self.progress(self.items, 'file')]
        return data, {'classes': self.classes}


def numbers_tree(root):
    for cls, split, name, value in [('even', 'train', 'a', 2),
                                    ('even', 'train', 'b', 4),
                                    ('odd', 'train', 'c', 3),
                                    ('odd', 'test', 'd', 5)]:
        (root / cls / split).mkdir(parents=True, exist_ok=True)
        (root / cls / split / f'{name}.num').write_text(str(value))


def test_folder_dataset_reads_caches_and_notices_changes(tmp_path):
    numbers_tree(tmp_path)
    Numbers.reads = 0
    train = Numbers(tmp_path)
    assert [float(d.x) for d in train] == [2, 4, 3]
    assert [int(d.y) for d in train] == [0, 0, 1]
    assert train.meta == {'classes': ['even', 'odd']}
    assert train.raw_dir == str(tmp_path)
    folder = tmp_path / PROCESSED
    assert {'numbers_train.pt', 'numbers_train_manifest.json',
            'numbers_train_meta.json'} <= set(os.listdir(folder))
    Numbers(tmp_path)
    assert Numbers.reads == 1  # cached
    (tmp_path / 'odd' / 'train' / 'e.num').write_text('7')
    assert [float(d.x) for d in Numbers(tmp_path)] == [2, 4, 3, 7]
    assert Numbers.reads == 2
    Numbers(tmp_path, force_reload=True)
    assert Numbers.reads == 3
    test = Numbers(str(tmp_path), 'test')
    assert [float(d.x) for d in test] == [5] and Numbers.reads == 4
    assert not [n for n in os.listdir(folder)
                if n.startswith(TEMPORARY_PREFIX)]


def test_pre_processing_gets_its_own_cache(tmp_path):
    numbers_tree(tmp_path)

    def double(data):
        data.x = 2 * data.x
        return data

    def odd_only(data):
        return int(data.y) == 1

    both = Numbers(tmp_path, pre_transform=double, pre_filter=odd_only)
    assert [float(d.x) for d in both] == [6]
    assert [float(d.x) for d in Numbers(tmp_path)] == [2, 4, 3]
    assert both.processed_dir != Numbers(tmp_path).processed_dir
    with pytest.raises(ValueError) as info:
        Numbers(tmp_path, pre_filter=lambda data: False)
    assert str(info.value) == (f"Numbers: 'pre_filter' removed every "
                               f"example of split 'train' in "
                               f"'{tmp_path}'")


def test_folder_dataset_errors_name_the_layout(tmp_path):
    with pytest.raises(ValueError) as info:
        Numbers(tmp_path / 'missing')
    assert str(info.value) == (f"Numbers: '{tmp_path / 'missing'}' is not a "
                               f"folder; expected the layout "
                               f"<class>/<train|test>/*.num")
    with pytest.raises(ValueError, match=r"Numbers: no class folders with a "
                       r"'train' or 'test' sub-folder in '.*'; expected the "
                       r"layout <class>/<train\|test>/\*\.num"):
        Numbers(tmp_path)
    (tmp_path / 'even' / 'test').mkdir(parents=True)
    (tmp_path / 'even' / 'test' / 'x.txt').write_text('not a number file')
    with pytest.raises(ValueError, match=r"Numbers: no \.num files for split "
                       r"'train' under '.*' \(classes: \['even'\]\)"):
        Numbers(tmp_path)
    with pytest.raises(ValueError, match=r"'split' must be one of"):
        Numbers(tmp_path, split='validation')
    # '~' is the user's home folder
    home = os.path.expanduser('~')
    with pytest.raises(ValueError, match=re.escape(
            osp.join(home, 'no-such-folder-tg-intrinsic'))):
        Numbers('~/no-such-folder-tg-intrinsic')
