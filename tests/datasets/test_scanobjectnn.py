import sys

import numpy as np
import pytest
import torch

from tg_intrinsic.datasets import ScanObjectNN

h5py = pytest.importorskip('h5py')
POINTS = 2048


def write_h5(path, num=3, label_dtype=np.uint8, mask=True, seed=0,
             labels=None, skip=()):
    """ScanObjectNN's h5 layout: 'data' [B, 2048, 3] float32, 'label' [B],
    'mask' [B, 2048] (-1 on background points)."""
    rng = np.random.default_rng(seed)
    data = rng.standard_normal((num, POINTS, 3)).astype(np.float32)
    label = np.asarray(labels if labels is not None else
                       rng.integers(0, 15, num), dtype=label_dtype)
    masks = np.where(rng.random((num, POINTS)) < 0.3, -1,
                     rng.integers(0, 5, (num, POINTS)))
    path.parent.mkdir(parents=True, exist_ok=True)
    with h5py.File(path, 'w') as f:
        if 'data' not in skip:
            f.create_dataset('data', data=data)
        if 'label' not in skip:
            f.create_dataset('label', data=label)
        if mask:
            f.create_dataset('mask', data=masks)
    return data, label, masks


def test_pb_t50_rs(tmp_path):
    folder = tmp_path / 'h5_files' / 'main_split'
    train = write_h5(folder / 'training_objectdataset_augmentedrot_scale75.h5')
    test = write_h5(folder / 'test_objectdataset_augmentedrot_scale75.h5',
                    num=2, label_dtype=np.int64, seed=1)
    for split, (data, label, mask) in [('train', train), ('test', test)]:
        ds = ScanObjectNN(str(tmp_path), split, log=False)
        assert len(ds) == len(data) and ds.num_classes == 15
        for i, item in enumerate(ds):
            assert torch.equal(item.pos, torch.from_numpy(data[i]))
            assert item.y.tolist() == [int(label[i])]
            assert torch.equal(item.object_mask,
                               torch.from_numpy(mask[i] != -1))
    assert ds.classes[0] == 'bag' and len(ds.classes) == 15
    assert "variant='PB_T50_RS'" in repr(ds)


def test_obj_only_and_obj_bg(tmp_path):
    h5 = tmp_path / 'h5_files'
    nobg, _, _ = write_h5(h5 / 'main_split_nobg' / 'training_objectdataset.h5',
                          mask=False)
    bg, _, _ = write_h5(h5 / 'main_split' / 'training_objectdataset.h5',
                        seed=2)
    # root may be h5_files itself
    only = ScanObjectNN(str(h5), variant='OBJ_ONLY', log=False)
    assert torch.equal(only[0].pos, torch.from_numpy(nobg[0]))
    assert 'object_mask' not in only[0]
    with_bg = ScanObjectNN(str(tmp_path), variant='OBJ_BG', log=False)
    assert torch.equal(with_bg[2].pos, torch.from_numpy(bg[2]))


def test_errors(tmp_path, monkeypatch):
    with pytest.raises(ValueError, match=r"found neither '.*h5_files/"
                       r"main_split/test_objectdataset\.h5'"):
        ScanObjectNN(str(tmp_path), 'test', variant='OBJ_BG')
    with pytest.raises(ValueError, match="'variant' must be one of"):
        ScanObjectNN(str(tmp_path), variant='PB_T25')
    path = tmp_path / 'main_split' / 'test_objectdataset.h5'
    write_h5(path, skip=('label', ))
    with pytest.raises(ValueError, match=r"could not read '.*test_object"
                       r"dataset\.h5': no dataset\(s\) \['label'\]"):
        ScanObjectNN(str(tmp_path), 'test', variant='OBJ_BG', log=False)
    write_h5(path, labels=[0, 15, 1])
    with pytest.raises(ValueError, match=r"objectdataset\.h5' holds the "
                       r"label 15 \(row 2\).*num_classes=15"):
        ScanObjectNN(str(tmp_path), 'test', variant='OBJ_BG', log=False)
    path.write_bytes(b'not an hdf5 file')
    with pytest.raises(ValueError, match=r"could not read '.*h5'"):
        ScanObjectNN(str(tmp_path), 'test', variant='OBJ_BG', log=False)
    monkeypatch.setitem(sys.modules, 'h5py', None)
    with pytest.raises(ImportError, match=r'pip install tg_intrinsic\[h5\]'):
        ScanObjectNN(str(tmp_path), 'test', variant='OBJ_BG', log=False)


def test_manifest_notices_changes(tmp_path):
    path = tmp_path / 'main_split' / 'training_objectdataset.h5'
    write_h5(path)
    assert len(ScanObjectNN(str(tmp_path), variant='OBJ_BG', log=False)) == 3
    data, _, _ = write_h5(path, num=4, seed=3)
    ds = ScanObjectNN(str(tmp_path), variant='OBJ_BG', log=False)
    assert len(ds) == 4 and torch.equal(ds[3].pos, torch.from_numpy(data[3]))
