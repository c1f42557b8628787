"""Opens a local data folder in whichever standard layout it has."""
import os
import os.path as osp
from typing import Optional

from .mesh_folder import MeshFolder
from .modelnet_resampled import ModelNetResampled
from .point_cloud_folder import PointCloudFolder
from .scanobjectnn import ScanObjectNN
from .shapenet_part_normal import ShapeNetPartNormal

POINT_EXTENSIONS = ('.txt', '.xyz', '.npy', '.pts')
# Formats that hold meshes only (.ply holds meshes or point clouds).
MESH_ONLY_EXTENSIONS = ('.obj', '.off')
MESH_EXTENSIONS = MESH_ONLY_EXTENSIONS + ('.ply', )
LAYOUTS = ('ModelNet40 resampled (modelnet40_shape_names.txt), ShapeNet-Part '
           '(synsetoffset2category.txt), ScanObjectNN (h5_files/main_split), '
           'meshes <class>/<train|test>/*.obj|off|ply or MeshCNN '
           'segmentation <train|test>/*.obj with seg/*.eseg, point clouds '
           '<class>/<train|test>/*.txt|xyz|npy|pts')


def _has_point_files(root: str) -> bool:
    """Whether the split folders (``<class>/<split>/`` or ``<split>/``)
    hold point files and no ``.obj`` or ``.off`` meshes; other files (a
    README.txt) do not count, nor does a file named like a mesh beside it
    (``a.txt`` beside ``a.ply``: MeshFolder's per-vertex labels)."""
    splits = ('train', 'test')
    folders = [osp.join(root, s) for s in splits]
    for name in os.listdir(root):
        folders += [osp.join(root, name, s) for s in splits]
    found = False
    for folder in folders:
        if not osp.isdir(folder):
            continue
        names = [osp.splitext(f) for f in os.listdir(folder)]
        if any(ext.lower() in MESH_ONLY_EXTENSIONS for _, ext in names):
            return False
        meshes = {stem for stem, ext in names
                  if ext.lower() in MESH_EXTENSIONS}
        found = found or any(ext.lower() in POINT_EXTENSIONS
                             and stem not in meshes for stem, ext in names)
    return found


def open_folder(root: str, split: str, task: str = 'classification',
                force_reload: bool = False, num_points: int = 10000,
                variant: str = 'PB_T50_RS', log: bool = True,
                cache_root: Optional[str] = None):
    r"""The :obj:`split` of the data set in the local folder :obj:`root`,
    read by the reader of its layout. The layout is recognised by its
    files:

    * :obj:`modelnet40_shape_names.txt` (or :obj:`modelnet10_*`):
      :class:`ModelNetResampled` (the first :obj:`num_points` points);
    * :obj:`synsetoffset2category.txt`: :class:`ShapeNetPartNormal`
      (training on :obj:`"trainval"`, as the papers do);
    * :obj:`h5_files/`, :obj:`main_split/` or :obj:`main_split_nobg/`:
      :class:`ScanObjectNN` (:obj:`variant`);
    * point files (:obj:`.txt`, :obj:`.xyz`, :obj:`.npy`, :obj:`.pts`)
      and no :obj:`.obj` or :obj:`.off` meshes: :class:`PointCloudFolder`;
      otherwise :class:`MeshFolder` (a :obj:`.txt` or :obj:`.npy` file
      named like a mesh beside it holds that mesh's labels).

    :obj:`log` is the reader's: whether it prints progress;
    :obj:`cache_root` too: where the processed files go instead of inside
    :obj:`root` (a read-only data set).

    Raises:
        ValueError: if :obj:`root` is not a folder, or from the reader,
            which names the layout it expected.
    """
    root = osp.expanduser(os.fspath(root))
    if not osp.isdir(root):
        raise ValueError(f"'{root}' is not a folder; expected one of the "
                         f"layouts: {LAYOUTS}")
    names = set(os.listdir(root))
    if names & {'modelnet40_shape_names.txt', 'modelnet10_shape_names.txt'}:
        num_classes = 40 if 'modelnet40_shape_names.txt' in names else 10
        return ModelNetResampled(root, split, num_classes=num_classes,
                                 num_points=num_points,
                                 force_reload=force_reload, log=log,
                                 cache_root=cache_root)
    if 'synsetoffset2category.txt' in names:
        return ShapeNetPartNormal(root, 'trainval' if split == 'train'
                                  else split, force_reload=force_reload,
                                  log=log, cache_root=cache_root)
    if names & {'h5_files', 'main_split', 'main_split_nobg'}:
        return ScanObjectNN(root, split, variant=variant,
                            force_reload=force_reload, log=log,
                            cache_root=cache_root)
    reader = PointCloudFolder if _has_point_files(root) else MeshFolder
    return reader(root, split, task=task, force_reload=force_reload,
                  log=log, cache_root=cache_root)
