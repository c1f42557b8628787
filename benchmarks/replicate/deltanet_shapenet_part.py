"""DeltaNet on ShapeNet-Part segmentation (DeltaConv, SIGGRAPH 2022,
Table 4; paper: 86.6 % instance-averaged mIoU).

Protocol ``deltanet-shapenet-part`` (:mod:`tg_intrinsic.protocols`, sources
in ``PROTOCOLS.md`` section 4): 2048 points per shape with the file's
normals, k = 30, convolutions 64-128-256, MLP depth 2, the object category
fed to the head, anisotropic scale U(2/3, 3/2) and translation 0.2, SGD 0.1
cosine to 1e-3, 200 epochs, batch 16; trained on train + val, scored on
test by the instance-averaged mIoU over each category's parts
(``metrics['final_test_miou']``) of the last epoch, one run.

Data: ``shapenetcore_partanno_segmentation_benchmark_v0_normal.zip``
(shapenet.cs.stanford.edu, as released with PointNet++), unpacked; PATH is
that folder, read by ``ShapeNetPartNormal``::

    shapenetcore_partanno_segmentation_benchmark_v0_normal/
    ├── synsetoffset2category.txt       "Airplane<TAB>02691156" per line
    ├── 02691156/1a04e3eab45ca15dd86060f189eb133.txt   "x y z nx ny nz part"
    ├── ...                             16 categories, 50 parts
    └── train_test_split/
        ├── shuffled_train_file_list.json   12137 shapes
        ├── shuffled_val_file_list.json      1870
        └── shuffled_test_file_list.json     2874

Usage::

    python benchmarks/replicate/deltanet_shapenet_part.py \\
        ~/data/shapenetcore_partanno_segmentation_benchmark_v0_normal
    python benchmarks/replicate/deltanet_shapenet_part.py --smoke
"""
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common  # noqa: E402
from _smoke_data import write_shapenet_part  # noqa: E402

ROW = _common.Row(
    protocol='deltanet-shapenet-part', reader='ShapeNetPartNormal',
    layout='shapenetcore_partanno_segmentation_benchmark_v0_normal/ with '
    'synsetoffset2category.txt, <synset>/<token>.txt and train_test_split/'
    'shuffled_{train,val,test}_file_list.json',
    smoke_data=write_shapenet_part,
    notes=('scored by one pass over the test shapes (the paper sums the '
           'logits of 10 randomly scaled and translated passes)',
           'the points are the file\'s, reduced to 2048 by Euclidean '
           'farthest point sampling (the paper: geodesic)'))


def main(argv=None):
    return _common.main(ROW, argv, __doc__)


if __name__ == '__main__':
    main()
