"""The row functions of README's results table, one module per method
(:mod:`report_rows.common` holds the registry and the number formats;
``benchmarks/report.py`` writes the table)."""
from . import deltaconv, gravo, hsn, library, svbrdf  # noqa: F401 (register)
from .common import ROWS, UNVERIFIED, ReportError, Row

#: the benchmarks in the table's order
ORDER = [
    'demo', 'neighbors', 'mesh_operators', 'normals', 'datasets',
    'deltaconv_speed', 'training_speed', 'deltanet_accuracy',
    'logmap_precompute', 'harmonic_conv_speed', 'gravo_mg',
    'gravo_applications', 'gravo_scale', 'gravo_diffusion',
    'compile_precision', 'hsn_accuracy', 'normalisation', 'cli_sweep',
    'svbrdf_accuracy', 'svbrdf_mitsuba', 'svbrdf_model_error', 'svbrdf_merge',
    'svbrdf_views', 'svbrdf_speed', 'svbrdf_capture_size',
    'part_segmentation', 'hsn_correspondence',
    'sphere_digits', 'perona_malik', 'out_of_core', 'ddp_training', 'gpu',
]

__all__ = ['ORDER', 'ROWS', 'UNVERIFIED', 'ReportError', 'Row']
