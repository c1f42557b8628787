"""DeltaNet on ModelNet40 classification (DeltaConv, SIGGRAPH 2022, Table 1;
paper: 93.8 % overall accuracy).

Protocol ``deltanet-modelnet40`` (:mod:`tg_intrinsic.protocols`, sources in
``PROTOCOLS.md`` section 1): 1024 points sampled from each mesh with their
triangle normals, k = 20, convolutions 64-64-128-256, anisotropic scale
U(0.8, 1.25) and translation 0.1, SGD 0.1 with a cosine schedule to 1e-3,
250 epochs, batch 32, label smoothing 0.2; the test accuracy of the last
epoch, one run.

Data: Princeton's mesh release ``ModelNet40.zip`` (modelnet.cs.princeton.edu),
unpacked. PATH is the ``ModelNet40`` folder, read by ``MeshFolder`` (labels:
the sorted class folders)::

    ModelNet40/
    ├── airplane/
    │   ├── train/airplane_0001.off ...
    │   └── test/airplane_0627.off ...
    ├── bathtub/
    └── ...           40 classes, 9843 train / 2468 test meshes

The resampled point release (``modelnet40_normal_resampled``) is not the
paper's input and is refused.

Usage::

    python benchmarks/replicate/deltanet_modelnet40.py ~/data/ModelNet40
    python benchmarks/replicate/deltanet_modelnet40.py --smoke
"""
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common  # noqa: E402
from _smoke_data import write_modelnet40  # noqa: E402

ROW = _common.Row(
    protocol='deltanet-modelnet40', reader='MeshFolder',
    layout='the ModelNet40 mesh release, ModelNet40/<class>/{train,test}/'
    '<class>_XXXX.off (ModelNet40.zip from modelnet.cs.princeton.edu)',
    smoke_data=write_modelnet40,
    notes=(_common.EUCLIDEAN_FPS, ))


def main(argv=None):
    return _common.main(ROW, argv, __doc__)


if __name__ == '__main__':
    main()
