"""``train``'s parts, one module per job: :mod:`~.sources` (data sets,
splits, the protocol), :mod:`~.prepare` (the shape pipelines and their
caches), :mod:`~.models`, :mod:`~.evaluation`, :mod:`~.checkpoints`,
:mod:`~.outputs` (the output folder, metrics, plots), :mod:`~.loop` (the
epoch loop) and :mod:`~.options` (the parser and the entry point).
:mod:`tg_intrinsic.train` is the face that keeps the old names."""
from .checkpoints import read_checkpoint
from .evaluation import evaluate, instance_miou
from .loop import seed_everything, train
from .models import build_model
from .options import add_arguments, main, parse_args
from .prepare import hsn_pipeline
from .sources import resolve_protocol

__all__ = [
    'train', 'evaluate', 'build_model', 'read_checkpoint',
    'resolve_protocol', 'hsn_pipeline', 'instance_miou',
    'seed_everything', 'add_arguments', 'parse_args', 'main',
]
