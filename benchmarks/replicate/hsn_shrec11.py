"""Harmonic Surface Network on SHREC'11 classification with 10 training
shapes per class (HSN, SIGGRAPH 2020, section 5.2; paper: 96.1 %).

Protocol ``hsn-shrec11`` (:mod:`tg_intrinsic.protocols`, sources in
``PROTOCOLS.md`` section 6): every mesh vertex, unit area, discs of radius
0.2 and 0.4 on two levels (a quarter of the vertices), 6 rings, rotation
orders 0 and 1, widths 16 and 32, rotations up to 45 degrees about x, y and
z and isotropic scale U(0.85, 1.15), Adam 1e-2 divided by 10 after epoch
20, 50 epochs, batch 1. Each of the 10 repeats draws 10 of the 16 training
meshes of every class (seeded by the repeat); the test set is the fixed
``test/`` folder (120 meshes). Reported: the mean last-epoch test accuracy.

Data: MeshCNN's simplified SHREC'11, ``shrec_16`` (``shrec_16.tar.gz``,
fetched by MeshCNN's ``scripts/shrec/get_data.sh``; HSN's ``shrec_16.zip``
holds the same meshes), read by ``MeshFolder``::

    shrec_16/
    ├── alien/
    │   ├── train/T1.obj ...     16 meshes of ~250 vertices
    │   └── test/T5.obj ...       4 meshes
    ├── ants/
    └── ...                      30 classes

Usage::

    python benchmarks/replicate/hsn_shrec11.py ~/data/shrec_16
    python benchmarks/replicate/hsn_shrec11.py --smoke
"""
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common  # noqa: E402
from _smoke_data import write_shrec16  # noqa: E402

ROW = _common.Row(
    protocol='hsn-shrec11', reader='MeshFolder',
    layout=_common.SHREC16_LAYOUT,
    smoke_data=write_shrec16,
    notes=(_common.FAST_LOG_MAPS, ))


def main(argv=None):
    return _common.main(ROW, argv, __doc__)


if __name__ == '__main__':
    main()
