"""open_folder: each standard layout (made here in miniature, in the
release's format) goes to its reader with the options that reader takes;
label files and notes beside meshes do not make a mesh folder a point
cloud folder; a path that is no folder names the layouts."""
import numpy as np
import pytest
import torch
import trimesh

from tg_intrinsic.datasets import (MeshFolder, ModelNetResampled,
                                   PointCloudFolder, ScanObjectNN,
                                   ShapeNetPartNormal, open_folder)
from tests.datasets import test_mesh_folder as meshes
from tests.datasets import test_modelnet_resampled as modelnet
from tests.datasets import test_point_cloud_folder as clouds
from tests.datasets import test_shapenet_part_normal as shapenet


def test_modelnet_resampled_release(tmp_path):
    modelnet.make_release(tmp_path)
    train = open_folder(tmp_path, 'train', num_points=12)
    assert type(train) is ModelNetResampled and len(train) == 4
    assert train.classes == ['airplane', 'bathtub', 'night_stand']
    assert train[0].pos.shape == (12, 3)  # num_points is passed on
    # without the ModelNet40 lists: the ModelNet10 release
    (tmp_path / 'modelnet40_shape_names.txt').unlink()
    ten = open_folder(tmp_path, 'test', num_points=12)
    assert type(ten) is ModelNetResampled
    assert ten.classes == ['bathtub', 'night_stand']
    assert len(ten) == 1  # night_stand only


def test_shapenet_part_trains_on_train_and_val(tmp_path):
    shapenet.make_release(tmp_path)
    train = open_folder(str(tmp_path), 'train')
    assert type(train) is ShapeNetPartNormal and train.split == 'trainval'
    assert len(train) == 4  # 3 train + 1 val, as the papers train
    test = open_folder(str(tmp_path), 'test')
    assert test.split == 'test' and len(test) == 2


def test_scanobjectnn_h5_files(tmp_path):
    pytest.importorskip('h5py')
    from tests.datasets.test_scanobjectnn import write_h5
    folder = tmp_path / 'h5_files' / 'main_split'
    data, _, _ = write_h5(folder / 'training_objectdataset.h5', num=2)
    write_h5(folder / 'test_objectdataset.h5', num=1, seed=1)
    train = open_folder(str(tmp_path), 'train', variant='OBJ_BG')
    assert type(train) is ScanObjectNN and train.variant == 'OBJ_BG'
    assert len(train) == 2
    assert torch.equal(train[0].pos, torch.from_numpy(data[0]))
    with pytest.raises(ValueError, match='augmentedrot_scale75'):
        open_folder(str(tmp_path), 'train')  # PB_T50_RS: not there


def test_point_clouds(tmp_path):
    clouds.classification_tree(tmp_path)
    (tmp_path / 'README.txt').write_text('a note at the top, not points')
    train = open_folder(str(tmp_path), 'train')
    assert type(train) is PointCloudFolder and len(train) == 4
    assert train.classes == ['chair', 'lamp']


def test_point_cloud_segmentation(tmp_path):
    clouds.segmentation_tree(tmp_path)
    train = open_folder(str(tmp_path), 'train', task='segmentation')
    assert type(train) is PointCloudFolder and train.task == 'segmentation'
    assert len(train) == 3 and train.num_classes == 5


def test_meshes_with_a_note_beside_them(tmp_path):
    meshes.make_tree(tmp_path)  # holds tet/train/notes.txt
    train = open_folder(str(tmp_path), 'train')
    assert type(train) is MeshFolder
    assert train.classes == ['cube', 'tet'] and len(train) == 3
    assert len(open_folder(str(tmp_path), 'test')) == 2


def test_meshes_with_label_files_beside_them(tmp_path):
    # MeshFolder's segmentation layout <split>/<stem>.obj + <stem>.txt: the
    # text files are labels, not point clouds
    mesh = trimesh.creation.icosphere(1)
    labels = (np.asarray(mesh.vertices)[:, 2] > 0).astype(int)
    for split in ('train', 'test'):
        (tmp_path / split).mkdir()
        for stem in ('a', 'b'):
            mesh.export(tmp_path / split / f'{stem}.obj')
            np.savetxt(tmp_path / split / f'{stem}.txt', labels, fmt='%d')
    train = open_folder(str(tmp_path), 'train', task='segmentation')
    assert type(train) is MeshFolder and len(train) == 2
    assert train[0].y.tolist() == labels.tolist()
    # the same with PLY meshes, which are also a point cloud format
    for path in (tmp_path / 'train').glob('*.obj'):
        path.unlink()
        mesh.export(path.with_suffix('.ply'))
    train = open_folder(str(tmp_path), 'train', task='segmentation',
                        force_reload=True)
    assert type(train) is MeshFolder and train[0].face.size(1) == 80


def test_force_reload_and_task_are_passed_on(tmp_path, monkeypatch):
    meshes.seg_tree(tmp_path)
    first = open_folder(str(tmp_path), 'train', task='segmentation')
    assert first.task == 'segmentation'
    from tg_intrinsic.datasets import mesh_folder
    calls = []
    read = mesh_folder.read_mesh
    monkeypatch.setattr(mesh_folder, 'read_mesh',
                        lambda path, **kw: calls.append(path) or
                        read(path, **kw))
    open_folder(str(tmp_path), 'train', task='segmentation')
    assert calls == []  # cached
    open_folder(str(tmp_path), 'train', task='segmentation',
                force_reload=True)
    assert len(calls) == 2


def test_a_path_that_is_no_folder_names_the_layouts(tmp_path):
    (tmp_path / 'data.zip').write_bytes(b'PK')
    for path in (tmp_path / 'missing', tmp_path / 'data.zip'):
        with pytest.raises(ValueError) as info:
            open_folder(str(path), 'train')
        message = str(info.value)
        assert f"'{path}' is not a folder" in message
        for layout in ('modelnet40_shape_names.txt',
                       'synsetoffset2category.txt', 'h5_files',
                       '<class>/<train|test>/*.obj|off|ply',
                       '*.txt|xyz|npy|pts'):
            assert layout in message


def test_an_empty_folder_is_read_as_meshes_which_name_their_layout(
        tmp_path):
    with pytest.raises(ValueError, match=r"MeshFolder: no class folders "
                       r"with a 'train' or 'test' sub-folder"):
        open_folder(str(tmp_path), 'train')
