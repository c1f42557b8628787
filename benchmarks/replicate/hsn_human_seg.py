"""Harmonic Surface Network on human body segmentation (Maron et al. 2017;
HSN, SIGGRAPH 2020, section 5.3; paper: 91.1 % per-vertex accuracy).

Protocol ``hsn-human-seg`` (:mod:`tg_intrinsic.protocols`, sources in
``PROTOCOLS.md`` section 7): 1024 vertices per mesh by farthest point
sampling, unit area, discs of radius 0.2 and 0.4 on two levels, 6 rings,
rotation orders 0 and 1, widths 16 and 32, rotations up to 45 degrees about
x, y and z and isotropic scale U(0.85, 1.15), Adam 1e-2 divided by 10 after
epoch 20, 50 epochs, batch 1; the per-vertex test accuracy of the last
epoch, one run.

**Data set.** The paper trained on HSN's repackaging of Maron et al.'s
data set (``shapeseg.zip``: 381 training shapes from Adobe, FAUST, MIT and
SCAPE, 18 SHREC'07 test shapes, labels per vertex). This script reads
MeshCNN's remeshed copy of the same shapes, ``human_seg`` (meshes of about
750 vertices, so the 1024-vertex resampling keeps them all; labels per
edge), which ``MeshFolder`` turns into per-vertex labels; the numbers are
therefore not directly comparable to the paper's.

Data: ``human_seg.tar.gz``, fetched by MeshCNN's
``scripts/human_seg/get_data.sh``; PATH is the ``human_seg`` folder::

    human_seg/
    ├── train/*.obj          381 meshes
    ├── test/*.obj            18 meshes
    ├── seg/<name>.eseg      one 1-based label per edge, MeshCNN's edge order
    └── sseg/<name>.seseg    soft labels, one row per edge (optional)

Usage::

    python benchmarks/replicate/hsn_human_seg.py ~/data/human_seg
    python benchmarks/replicate/hsn_human_seg.py --smoke
"""
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common  # noqa: E402
from _smoke_data import write_human_seg  # noqa: E402

ROW = _common.Row(
    protocol='hsn-human-seg', reader='MeshFolder',
    layout=_common.HUMAN_SEG_LAYOUT,
    smoke_data=write_human_seg,
    notes=(_common.HUMAN_SEG_COPY,
           _common.FAST_LOG_MAPS))


def main(argv=None):
    return _common.main(ROW, argv, __doc__)


if __name__ == '__main__':
    main()
