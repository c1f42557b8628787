"""DeltaNet on SHREC'11 classification with 10 training shapes per class
(DeltaConv, SIGGRAPH 2022, Table 3; the paper's number is not verified).

Protocol ``deltanet-shrec11`` (:mod:`tg_intrinsic.protocols`, sources in
``PROTOCOLS.md`` section 3): 2048 points sampled from each mesh with their
triangle normals, k = 20, convolutions 32-32-32-32, random rotations (SO(3))
and translation 0.1, SGD 0.1 cosine to 1e-3, 100 epochs, batch 16, label
smoothing 0.2. Each of the 10 repeats draws 10 of the 16 training meshes of
every class (seeded by the repeat); the test set is the fixed ``test/``
folder (4 per class, 120 meshes). Reported: the mean of the last-epoch test
accuracies.

Data: MeshCNN's simplified SHREC'11, ``shrec_16`` (``shrec_16.tar.gz``,
fetched by MeshCNN's ``scripts/shrec/get_data.sh``), read by ``MeshFolder``
(labels: the sorted class folders)::

    shrec_16/
    ├── alien/
    │   ├── train/T1.obj ...     16 meshes of ~250 vertices
    │   └── test/T5.obj ...       4 meshes
    ├── ants/
    └── ...                      30 classes

Usage::

    python benchmarks/replicate/deltanet_shrec11.py ~/data/shrec_16
    python benchmarks/replicate/deltanet_shrec11.py --smoke
"""
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common  # noqa: E402
from _smoke_data import write_shrec16  # noqa: E402

ROW = _common.Row(
    protocol='deltanet-shrec11', reader='MeshFolder',
    layout=_common.SHREC16_LAYOUT,
    smoke_data=write_shrec16,
    notes=(_common.EUCLIDEAN_FPS, ))


def main(argv=None):
    return _common.main(ROW, argv, __doc__)


if __name__ == '__main__':
    main()
