"""Prints the versions of the library and its dependencies, the compute
device, and which optional extras are installed."""
import importlib
import importlib.metadata
import json
import re

from tg_intrinsic.extras import EXTRAS

HELP = 'versions, device and optional extras'
EXAMPLE = """example:
  tg-intrinsic info          # a table
  tg-intrinsic info --json   # the same as JSON, for bug reports
"""

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
    info['extras'] = {
        name: {'installed': {_distribution(r): _installed(_distribution(r))
                             for r in requirements},
               'needed_by': needed_by,
               'install': f'pip install "tg_intrinsic[{name}]"'}
        for name, (requirements, needed_by) in EXTRAS.items()}
    return info


def _distribution(requirement: str) -> str:
    """The distribution a requirement names ('h5py>=3.8' -> 'h5py')."""
    return re.split(r'[<>=!~;\[ ]', requirement, maxsplit=1)[0]


def _installed(distribution: str):
    """The installed version of ``distribution``, or None."""
    try:
        return importlib.metadata.version(distribution)
    except importlib.metadata.PackageNotFoundError:
        return None


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
    print('optional extras (pip install "tg_intrinsic[NAME]"):')
    width = max(map(len, info['extras']))
    for name, extra in info['extras'].items():
        missing = [d for d, v in extra['installed'].items() if v is None]
        if missing:
            state = f"missing {', '.join(missing)}"
        elif len(extra['installed']) == 1:
            state = 'installed ({} {})'.format(*next(iter(
                extra['installed'].items())))
        else:
            state = 'installed'
        print(f"  {name:<{width}}  {state}: {extra['needed_by']}")
    return 0
