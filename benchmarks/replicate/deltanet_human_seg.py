"""DeltaNet on human body segmentation (Maron et al. 2017; DeltaConv,
SIGGRAPH 2022, supplement; the paper's number is not verified).

Protocol ``deltanet-human-seg`` (:mod:`tg_intrinsic.protocols`, sources in
``PROTOCOLS.md`` section 5): 1024 points sampled from each mesh (each takes
the label of its triangle's nearest corner), k = 20, eight convolutions of
128, embedding 512, rotation about z, anisotropic scale U(0.8, 1.2),
translation 0.1, Adam 5e-3 divided by 10 after epoch 30, 50 epochs, batch
8; the per-point test accuracy of the last epoch, one run.

**Data set.** The paper trained on HSN's repackaging of Maron et al.'s
data set (``shapeseg.zip``: 381 training shapes from Adobe, FAUST, MIT and
SCAPE, 18 SHREC'07 test shapes, labels per vertex). This script reads
MeshCNN's remeshed copy of the same shapes, ``human_seg`` (meshes of about
750 vertices, labels per edge), which ``MeshFolder`` turns into per-vertex
labels; the numbers are therefore not directly comparable to the paper's.

Data: ``human_seg.tar.gz``, fetched by MeshCNN's
``scripts/human_seg/get_data.sh``; PATH is the ``human_seg`` folder::

    human_seg/
    ├── train/*.obj          381 meshes
    ├── test/*.obj            18 meshes
    ├── seg/<name>.eseg      one 1-based label per edge, MeshCNN's edge order
    └── sseg/<name>.seseg    soft labels, one row per edge (optional)

Usage::

    python benchmarks/replicate/deltanet_human_seg.py ~/data/human_seg
    python benchmarks/replicate/deltanet_human_seg.py --smoke
"""
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common  # noqa: E402
from _smoke_data import write_human_seg  # noqa: E402

ROW = _common.Row(
    protocol='deltanet-human-seg', reader='MeshFolder',
    layout=_common.HUMAN_SEG_LAYOUT,
    smoke_data=write_human_seg,
    notes=(_common.HUMAN_SEG_COPY,
           'reported at the last epoch (the paper: at the best epoch on 10 % '
           'of the training set held out)'))


def main(argv=None):
    return _common.main(ROW, argv, __doc__)


if __name__ == '__main__':
    main()
