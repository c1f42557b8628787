"""DeltaNet on ScanObjectNN, variant PB_T50_RS (DeltaConv, SIGGRAPH 2022,
Table 2; paper: 84.7 % overall accuracy).

Protocol ``deltanet-scanobjectnn`` (:mod:`tg_intrinsic.protocols`, sources in
``PROTOCOLS.md`` section 2): 1024 of each scan's 2048 points, normals
estimated (k = 10), k = 20, regulariser 1e-2, convolutions 64-64-64-128,
rotation about the vertical y axis, anisotropic scale U(0.8, 1.25),
translation 0.1, SGD 0.1 cosine to 1e-3, 250 epochs, batch 32, label
smoothing 0.2; the test accuracy of the last epoch, one run.

Data: the ScanObjectNN h5 files (request them from the authors, see
hkust-vgd.github.io/scanobjectnn), read by ``ScanObjectNN``. PATH is the
folder holding ``h5_files`` (or ``h5_files`` itself)::

    ScanObjectNN/
    └── h5_files/
        ├── main_split/
        │   ├── training_objectdataset_augmentedrot_scale75.h5   11416 scans
        │   ├── test_objectdataset_augmentedrot_scale75.h5        2882 scans
        │   └── ...       (the other variants' files are not read)
        └── main_split_nobg/ ...

Each file holds ``data`` (B, 2048, 3), ``label`` (B,) in 0-14 and ``mask``.

Usage::

    python benchmarks/replicate/deltanet_scanobjectnn.py ~/data/ScanObjectNN
    python benchmarks/replicate/deltanet_scanobjectnn.py --smoke
"""
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common  # noqa: E402
from _smoke_data import write_scanobjectnn  # noqa: E402

ROW = _common.Row(
    protocol='deltanet-scanobjectnn', reader='ScanObjectNN',
    layout='ScanObjectNN\'s h5_files/main_split/{training,test}_'
    'objectdataset_augmentedrot_scale75.h5 (PB_T50_RS; PATH holds h5_files '
    'or is h5_files)',
    smoke_data=write_scanobjectnn,
    notes=('the 2048 points are reduced to 1024 by Euclidean farthest point '
           'sampling (the paper: geodesic)', ))


def main(argv=None):
    return _common.main(ROW, argv, __doc__)


if __name__ == '__main__':
    main()
