"""Prints the versions of the library and its dependencies, the compute
device, and which optional extras are installed."""
import importlib
import json

HELP = 'versions, device and optional extras'
EXAMPLE = """example:
  tg-intrinsic info          # a table
  tg-intrinsic info --json   # the same as JSON, for bug reports
"""

# (import name, what it adds, how to get it)
EXTRAS = (
    ('potpourri3d', "log maps with method='vector_heat'", 'pip install '
     'tg_intrinsic[heat]'),
    ('OpenEXR', 'reading .exr images and environment maps',
     'pip install tg_intrinsic[exr]'),
    ('mitsuba', 'the external renderer of the SVBRDF oracle and benchmark',
     'pip install tg_intrinsic[mitsuba]'),
    ('torch_scatter', 'compiled scatter kernels (results do not change)',
     'pip install tg_intrinsic[scatter]'),
)


def add_arguments(parser):
    parser.add_argument('--json', action='store_true',
                        help='print JSON instead of a table')


def _version(name):
    try:
        module = importlib.import_module(name)
    except Exception:  # noqa: BLE001 - absent or broken: both "missing"
        return None
    return str(getattr(module, '__version__', 'installed'))


def collect() -> dict:
    """Everything ``info`` reports, as a dict."""
    import torch
    import tg_intrinsic
    from tg_intrinsic.utils import machine_info
    info = machine_info()
    info['tg_intrinsic'] = tg_intrinsic.__version__
    for name in ('trimesh', 'pyamg', 'robust_laplacian', 'matplotlib'):
        info[name] = _version(name)
    info['device'] = 'cuda' if torch.cuda.is_available() else 'cpu'
    info['cuda_version'] = torch.version.cuda
    info['extras'] = {name: {'version': _version(name), 'adds': adds,
                             'install': how}
                      for name, adds, how in EXTRAS}
    return info


def run(args):
    info = collect()
    if args.json:
        print(json.dumps(info, indent=2))
        return 0
    rows = [('tg_intrinsic', info['tg_intrinsic']),
            ('python', info['python']), ('torch', info['torch']),
            ('torch_geometric', info['torch_geometric']),
            ('numpy', info['numpy']), ('scipy', info['scipy']),
            ('numba', info.get('numba')), ('trimesh', info['trimesh']),
            ('pyamg', info['pyamg']),
            ('robust_laplacian', info['robust_laplacian']),
            ('platform', info['platform']),
            ('cpu cores / torch threads',
             f"{info['cpu_count']} / {info['torch_threads']}"),
            ('device', info['cuda'] or 'cpu (no CUDA device)')]
    width = max(len(name) for name, _ in rows)
    for name, value in rows:
        print(f"{name:<{width}}  {value}")
    print('optional extras:')
    for name, extra in info['extras'].items():
        state = extra['version'] or f"missing ({extra['install']})"
        print(f"  {name:<14} {state}: {extra['adds']}")
    return 0
