"""Precomputes what a model or solver needs for every mesh or point cloud
in a folder (or one file), once, in parallel, resumably: DeltaConv
operators (mls), geodesic discs with log map and transport (logmap), the
whole Harmonic Surface Network pipeline training uses (hsn), or a Gravo MG
hierarchy (gravo).

Every OBJ/OFF/PLY/STL file under INPUT (recursively, sorted) becomes a
PyG Data object saved with torch.save at the same relative path under
OUTPUT, extension .pt (load it with torch.load(path, weights_only=False)).
Files are written atomically, so a killed run leaves only whole files and
the next run skips them; OUTPUT/precompute.json records the kind and the
settings, and a rerun with other settings stops unless --overwrite. Files
that fail are listed at the end and in OUTPUT/failures.json (exit code 2);
the others are still written."""
import json
import os
import shutil
import textwrap
import time
import traceback
from typing import Dict, List, Optional, Tuple

from tg_intrinsic.errors import interruption_behind

from .common import (ArgumentParser, UsageError, common_options, default_of,
                     int_at_least,
                     nonnegative_float, nonnegative_int, one_line,
                     positive_float, positive_int)

HELP = 'precompute operators, log maps or hierarchies for a folder of meshes'
EXAMPLE = """examples:
  tg-intrinsic precompute mls clouds/ cache/mls --k 20 --workers 4
  tg-intrinsic precompute hsn meshes/ cache/hsn --radius 0.2 --rings 6
  tg-intrinsic precompute logmap bunny.obj bunny_logmap.pt --radius 0.05
  tg-intrinsic precompute gravo scans/ cache/gravo --ratio 8 --lower-bound 500

Run "tg-intrinsic precompute KIND --help" for the options of each kind.
Rerunning the same command resumes: files already written are skipped,
and the temporary files (.tmp-*) of a run killed while saving are removed.
Runs on the CPU, one process per --workers (numba and scipy kernels); the
saved tensors load onto any device."""

MANIFEST = 'precompute.json'
FAILURES = 'failures.json'
DTYPES = ('float32', 'float64')

# kind: (help, description)
KINDS = {
    'mls': ('DeltaConv gradient and divergence (meshes and point clouds)',
            "DeltaConv's moving-least-squares gradient and divergence on "
            "the k-nn graph of the points (MLSOperators): edge_index, "
            "frame, grad_weight, div_weight and normal. Normals come from "
            "the PLY properties nx ny nz, else from the mesh, else are "
            "estimated from the --normal-k nearest neighbours."),
    'logmap': ('geodesic discs with log map and transport (meshes)',
               "Geodesic discs of --radius around every vertex with the log "
               "map of every neighbour and the parallel transport angle "
               "(LogMap): edge_index, logmap, transport, area, frame. "
               "Triangle meshes only."),
    'hsn': ('the Harmonic Surface Network pipeline of training (meshes)',
            "The precomputation Harmonic Surface Networks train on, the "
            "same as 'tg-intrinsic train hsn': unit area, log maps and "
            "transport on two levels (radius and twice the radius), "
            "circular-harmonic terms (NormalizeArea, LogMap, "
            "MultiscaleSupports, HarmonicPrecompute). Triangle meshes only."),
    'gravo': ('a Gravo MG multigrid hierarchy (meshes and point clouds)',
              "A Gravo MG hierarchy (GravoHierarchy) on the mesh edges, or "
              "on the --k nearest neighbour graph of a point cloud: pos_l, "
              "edge_index_l, prolong_index_l, prolong_weight_l, ... per "
              "level."),
}


def add_arguments(parser):
    from tg_intrinsic.geometry.geodesics.logmap import METHODS
    from tg_intrinsic.geometry.pointcloud.mls import MIN_MLS_NEIGHBOURS
    from tg_intrinsic.training.prepare import hsn_pipeline
    from tg_intrinsic.transforms import (EstimateNormals, GravoHierarchy,
                                         MLSOperators)
    kinds = parser.add_subparsers(dest='kind', metavar='KIND', required=True,
                                  parser_class=ArgumentParser)
    for kind, (short, description) in KINDS.items():
        sub = kinds.add_parser(kind, parents=[common_options()], help=short,
                               description=textwrap.fill(
                                   description, 78, break_on_hyphens=False),
                               epilog=EXAMPLE,
                               formatter_class=parser.formatter_class)
        sub.add_argument('input', metavar='INPUT',
                         help='a mesh or point cloud file, or a folder '
                         'searched recursively for OBJ/OFF/PLY/STL files')
        sub.add_argument('output', metavar='OUTPUT',
                         help='the output folder (or, for one INPUT file, '
                         'a .pt file)')
        sub.add_argument('--workers', type=positive_int, default=1,
                         help='files processed in parallel, one process '
                         'and one thread each; the results do not depend on '
                         'it (default: %(default)s)')
        sub.add_argument('--overwrite', action='store_true',
                         help='recompute every file, also those done, and '
                         'replace the settings recorded in OUTPUT')
        sub.add_argument('--dtype', choices=DTYPES, default='float32',
                         help='floating type of the saved tensors and of '
                         'the computation (default: %(default)s, what the '
                         'models train in)')
        if kind == 'mls':
            sub.add_argument('--k', type=int_at_least(MIN_MLS_NEIGHBOURS),
                             default=default_of(MLSOperators, 'k'),
                             help='neighbours of every point, itself '
                             'included (default: %(default)s)')
            sub.add_argument('--regularizer', type=nonnegative_float,
                             default=default_of(MLSOperators, 'regularizer'),
                             help='Tikhonov weight of the least-squares '
                             'fits (default: %(default)s)')
            sub.add_argument('--normal-k', type=int_at_least(2),
                             default=default_of(EstimateNormals, 'k'),
                             help='neighbours for estimated normals '
                             '(default: %(default)s)')
        if kind in ('logmap', 'hsn'):
            sub.add_argument('--radius', type=positive_float,
                             default=default_of(hsn_pipeline, 'radius'),
                             help='disc radius (default: %(default)s); '
                             + ('on the unit-area mesh' if kind == 'hsn'
                                else 'in mesh units, or on the unit-area '
                                'mesh with --unit-area'))
            sub.add_argument('--method', choices=METHODS,
                             default=default_of(hsn_pipeline, 'method'),
                             help="log map and transport: 'fast' (tangent "
                             "projection rescaled to arc length) or "
                             "'vector_heat' (default: %(default)s)")
        if kind == 'logmap':
            sub.add_argument('--unit-area', action='store_true',
                             help='scale every mesh to unit area first')
        if kind == 'hsn':
            sub.add_argument('--rings', type=positive_int,
                             default=default_of(hsn_pipeline, 'rings'),
                             help='radial rings of the filters (default: '
                             '%(default)s)')
            sub.add_argument('--max-order', type=nonnegative_int,
                             default=default_of(hsn_pipeline, 'max_order'),
                             help='highest rotation order (default: '
                             '%(default)s)')
        if kind == 'gravo':
            sub.add_argument('--ratio', type=positive_float,
                             default=default_of(GravoHierarchy, 'ratio'),
                             help='each level keeps about 1/RATIO of the '
                             'points (default: %(default)s)')
            sub.add_argument('--lower-bound', type=positive_int,
                             default=default_of(GravoHierarchy,
                                                'lower_bound'),
                             help='smallest level size; smaller surfaces get '
                             'no levels (default: %(default)s)')
            sub.add_argument('--k', type=positive_int,
                             default=default_of(GravoHierarchy, 'k'),
                             help='neighbours of the graph of point clouds '
                             '(default: %(default)s)')


def settings_of(args) -> Dict:
    """The settings a result depends on (recorded in the manifest)."""
    names = {'mls': ('k', 'regularizer', 'normal_k'),
             'logmap': ('radius', 'method', 'unit_area'),
             'hsn': ('radius', 'rings', 'max_order', 'method'),
             'gravo': ('ratio', 'lower_bound', 'k')}[args.kind]
    return {'dtype': args.dtype, **{name: getattr(args, name)
                                    for name in names}}


# ----------------------------------------------------------------------
# One file (runs in the worker processes; everything here is picklable)

def transform_of(kind: str, settings: Dict):
    """The transform that precomputes ``kind`` with ``settings``."""
    from torch_geometric.transforms import Compose
    from tg_intrinsic.transforms import (EstimateNormals, GravoHierarchy,
                                         LogMap, MLSOperators, NormalizeArea)
    if kind == 'mls':
        return Compose([EstimateNormals(k=settings['normal_k']),
                        MLSOperators(k=settings['k'],
                                     regularizer=settings['regularizer'])])
    if kind == 'logmap':
        steps = [NormalizeArea()] if settings['unit_area'] else []
        return Compose(steps + [LogMap(settings['radius'],
                                       method=settings['method'])])
    if kind == 'hsn':
        from tg_intrinsic.training.prepare import hsn_pipeline
        return hsn_pipeline(settings['radius'], settings['rings'],
                            settings['max_order'], settings['method'])
    if kind == 'gravo':
        return GravoHierarchy(ratio=settings['ratio'],
                              lower_bound=settings['lower_bound'],
                              k=settings['k'])
    raise ValueError(f"unknown kind {kind!r}; choose one of {list(KINDS)}")


def load_surface(path: str, kind: str, dtype: str):
    """Reads ``path`` into an :class:`~tg_intrinsic.data.IntrinsicData`
    (``pos``, ``face`` for meshes, ``normal`` from PLY ``nx ny nz``) and
    rejects what ``kind`` cannot handle."""
    import numpy as np
    import torch
    from tg_intrinsic.data import IntrinsicData
    from tg_intrinsic.io import read_surface
    pos, face, properties = read_surface(path)
    if face is None and kind in ('logmap', 'hsn'):
        raise ValueError(f"'{path}' is a point cloud but {kind} needs a "
                         f"triangle mesh (geodesic discs); use 'mls' or "
                         f"'gravo' for point clouds")
    if len(pos) < 2:
        raise ValueError(f"'{path}' has only {len(pos)} point")
    float_type = getattr(torch, dtype)
    data = IntrinsicData(pos=torch.from_numpy(pos).to(float_type))
    if face is not None:
        data.face = torch.from_numpy(face).t().contiguous()
    if all(name in properties for name in ('nx', 'ny', 'nz')):
        normal = np.stack([properties[name] for name in ('nx', 'ny', 'nz')],
                          1).astype(np.float64)
        length = np.linalg.norm(normal, axis=1)
        bad = ~np.isfinite(length) | (length < 1e-12)
        if bad.any():
            raise ValueError(f"'{path}' has {int(bad.sum())} zero, NaN or "
                             f"infinite normal(s) in nx ny nz; repair them "
                             f"or remove the properties to estimate normals")
        data.normal = torch.from_numpy(normal / length[:, None]).to(
            float_type)
    return data


def _check_neighbours(data, kind: str, settings: Dict, source: str):
    """A neighbour count above the points of a file, named by its option
    (the transforms only know their own argument names)."""
    n = data.num_nodes
    estimated = 'normal' not in data and 'face' not in data
    options = {'mls': [('--k', 'k')] + ([('--normal-k', 'normal_k')]
                                        if estimated else []),
               'gravo': [] if 'face' in data else [('--k', 'k')]}
    for option, name in options.get(kind, []):
        if settings[name] > n:
            raise ValueError(f"'{source}' has {n} points, fewer than "
                             f"{option} {settings[name]}; lower {option} to "
                             f"at most {n}")


def precompute_file(kind: str, settings: Dict, source: str, target: str):
    """Precomputes one file and saves the result atomically."""
    from tg_intrinsic.utils import atomic_torch_save
    data = load_surface(source, kind, settings['dtype'])
    _check_neighbours(data, kind, settings, source)
    data = transform_of(kind, settings)(data)
    atomic_torch_save(data, target)


def _work(task) -> Tuple[str, Optional[str], Optional[str]]:
    """(source, reason or None, traceback of an unexpected error or None)."""
    from tg_intrinsic.cli import USER_ERRORS
    kind, settings, source, target = task
    try:
        precompute_file(kind, settings, source, target)
        return source, None, None
    except USER_ERRORS as error:  # a bad file: its message says why
        return source, one_line(error), None
    except Exception as error:  # noqa: BLE001 - reported per file
        stop = interruption_behind(error)
        if stop is not None:  # Ctrl-C inside a compiled function
            raise stop from None
        return (source, f"unexpected {type(error).__name__}: "
                f"{one_line(error)}", traceback.format_exc())


# ----------------------------------------------------------------------
# Files, manifest, pool

def find_inputs(folder: str, skip: Optional[str] = None) -> List[str]:
    """Every OBJ/OFF/PLY/STL file under ``folder``, recursively, sorted
    (hidden files and folders and the folder ``skip`` left out). Linked
    folders are followed, each real folder once (a link to a parent
    would loop)."""
    from tg_intrinsic.io.mesh import MESH_EXTENSIONS
    skip = os.path.realpath(skip) if skip else None
    found, seen = [], {os.path.realpath(folder)}

    def new(path):
        real = os.path.realpath(path)
        if real == skip or real in seen:
            return False
        seen.add(real)
        return True
    for root, dirs, files in os.walk(folder, followlinks=True):
        dirs[:] = sorted(d for d in dirs if not d.startswith('.') and
                         new(os.path.join(root, d)))
        for name in files:
            if not name.startswith('.') and \
                    os.path.splitext(name)[1].lower() in MESH_EXTENSIONS:
                found.append(os.path.join(root, name))
    return sorted(found, key=lambda p: os.path.relpath(p, folder))


def plan(input_path: str, output: str) -> Tuple[List[Tuple[str, str]],
                                                  bool]:
    """The (source, target) pairs, and whether ``output`` is a folder
    (with a manifest) rather than one .pt file."""
    from tg_intrinsic.io.mesh import MESH_EXTENSIONS
    if not os.path.exists(input_path):
        raise FileNotFoundError(f"INPUT '{input_path}' does not exist")
    if os.path.exists(output) and not os.path.isdir(output) and not \
            (os.path.isfile(input_path) and output.lower().endswith('.pt')):
        raise UsageError(f"OUTPUT '{output}' is a file; give a folder (or, "
                         f"for one INPUT file, a .pt file)")
    if os.path.isdir(output) and output.lower().endswith('.pt') and \
            os.path.isfile(input_path):
        raise UsageError(f"OUTPUT '{output}' is a folder, not a .pt file; "
                         f"give a .pt file name that is free, or a folder "
                         f"name without .pt to write into")
    if os.path.isfile(input_path):
        if os.path.splitext(input_path)[1].lower() not in MESH_EXTENSIONS:
            raise UsageError(f"INPUT '{input_path}' is not a mesh or point "
                             f"cloud file ({'/'.join(MESH_EXTENSIONS)})")
        if output.lower().endswith('.pt'):
            return [(input_path, output)], False
        stem = os.path.splitext(os.path.basename(input_path))[0]
        return [(input_path, os.path.join(output, stem + '.pt'))], True
    if output.lower().endswith('.pt'):
        raise UsageError(f"OUTPUT '{output}' is a .pt file but INPUT is a "
                         f"folder; give an output folder")
    sources = find_inputs(input_path, skip=output)
    if not sources:
        raise UsageError(f"INPUT '{input_path}' holds no "
                         f"{'/'.join(MESH_EXTENSIONS)} files (searched "
                         f"recursively)")
    pairs, seen = [], {}
    for source in sources:
        rel = os.path.relpath(source, input_path)
        target = os.path.join(output, os.path.splitext(rel)[0] + '.pt')
        if target in seen:
            raise UsageError(f"'{seen[target]}' and '{source}' would both be "
                             f"written to '{target}'; rename one of them")
        seen[target] = source
        pairs.append((source, target))
    return pairs, True


def _read_manifest(path: str) -> Optional[Dict]:
    """The manifest at ``path``, :obj:`None` when missing; a
    :class:`UsageError` when unreadable."""
    if not os.path.exists(path):
        return None
    try:
        with open(path) as f:
            old = json.load(f)
        if not {'kind', 'settings'} <= set(old):
            raise KeyError('kind and settings')
        return old
    except (OSError, ValueError, KeyError, TypeError) as error:
        raise UsageError(f"cannot read '{path}' ({one_line(error)}); "
                         f"delete it or rerun with --overwrite") from None


def _changes(old: Dict, manifest: Dict) -> List[str]:
    changes = [f"kind {old['kind']} -> {manifest['kind']}"] \
        if old['kind'] != manifest['kind'] else []
    return changes + [f"{key} {old['settings'].get(key)!r} -> {value!r}"
                      for key, value in manifest['settings'].items()
                      if old['settings'].get(key) != value]


def _own_results(manifest: Optional[Dict]) -> Optional[set]:
    """The results (relative paths) a manifest says precompute wrote;
    :obj:`None` for no manifest, or one of a version that kept no list
    (then every .pt file counts as precompute's)."""
    if manifest is None or not isinstance(manifest.get('files'), list):
        return None
    return {str(name) for name in manifest['files']}


def _foreign_files(output: str, manifest: Optional[Dict]) -> List[str]:
    """Files under ``output`` that precompute did not write: all but its
    manifest, failure list, the results its manifest lists and, beside a
    manifest, the temporary files of a run killed while saving."""
    from tg_intrinsic.io.results import RECORD, files_under
    from tg_intrinsic.utils import is_temporary
    own = _own_results(manifest)
    return [name for name in files_under(output)
            if name not in (MANIFEST, FAILURES, RECORD) and not (
                name in own if own is not None else
                manifest is not None and name.endswith('.pt'))
            and not (manifest is not None and is_temporary(name))]


def choose_folder(output: str, manifest: Dict, overwrite: bool,
                  targets: List[str]) -> str:
    """Where this run writes, after checking ``output``: ``output`` itself
    for a new folder or a resumed run, else (``overwrite`` over earlier
    results) a staging folder beside it whose files replace the earlier
    ones only when every file is done (:func:`commit_staging`), so a
    failed run never mixes settings. Stops on other settings, results of
    unknown settings or files precompute did not write, unless
    ``overwrite``. Records ``manifest`` in the folder chosen."""
    from tg_intrinsic.utils import atomic_write_json
    old = _read_manifest(os.path.join(output, MANIFEST)) \
        if not overwrite else None
    if old is not None and _changes(old, manifest):
        raise UsageError(f"'{output}' was made with other settings "
                         f"({', '.join(_changes(old, manifest))}); rerun "
                         f"with --overwrite to recompute every file, or "
                         f"give another OUTPUT")
    owned = os.path.exists(os.path.join(output, MANIFEST))
    foreign = _foreign_files(output, old if old is not None or not owned
                             else _read_manifest(os.path.join(output,
                                                              MANIFEST)))
    if foreign and not overwrite:
        # .pt files beside a manifest that does not list them are the
        # user's; without a manifest they may be results of unknown settings
        unknown = [] if owned else [name for name in foreign
                                    if name.endswith('.pt')]
        if unknown:
            raise UsageError(f"'{output}' holds results ({unknown[0]}, ...) "
                             f"but no {MANIFEST}, so their settings are "
                             f"unknown; rerun with --overwrite to recompute "
                             f"them, or give another OUTPUT")
        raise UsageError(f"OUTPUT '{output}' holds files precompute did not "
                         f"write ({', '.join(foreign[:3])}"
                         f"{', ...' if len(foreign) > 3 else ''}); give a "
                         f"new or empty folder, or --overwrite to write "
                         f"there anyway (those files are kept)")
    earlier = owned or any(os.path.exists(t) for t in targets)
    folder = staging_folder(output) if overwrite and earlier else output
    if folder != output:
        kept = _read_manifest(os.path.join(folder, MANIFEST)) \
            if os.path.isdir(folder) else None
        if kept is None or _changes(kept, manifest):
            shutil.rmtree(folder, ignore_errors=True)  # other settings
    # the results this folder will hold, so that a later --overwrite
    # removes precompute's own stale files and nothing else
    files = {os.path.relpath(target, output) for target in targets}
    if folder == output and old is not None:  # resumed: earlier ones stay
        files |= {name for name in _own_results(old) or ()
                  if os.path.isfile(os.path.join(output, name))}
    os.makedirs(folder, exist_ok=True)
    atomic_write_json(os.path.join(folder, MANIFEST),
                      {**manifest, 'files': sorted(files)})
    return folder


def staging_folder(output: str) -> str:
    """The folder beside ``output`` where ``--overwrite`` computes."""
    parent, name = os.path.split(os.path.abspath(output))
    return os.path.join(parent, f'.{name}.overwrite')


def commit_staging(staging: str, output: str, targets: List[str]):
    """Replaces the earlier results in ``output`` by those in
    ``staging``: the old manifest goes first (so no moment claims
    settings the files do not hold), then every result, then the new
    manifest; earlier results of files no longer in INPUT are removed
    (only those the old manifest lists: every other file is the user's)."""
    old_manifest = os.path.join(output, MANIFEST)
    earlier = _own_results(_read_manifest(old_manifest)) or set() \
        if os.path.exists(old_manifest) else set()
    if os.path.exists(old_manifest):
        os.remove(old_manifest)
    keep = {os.path.relpath(t, output) for t in targets}
    for name in sorted(earlier - keep):
        try:
            os.remove(os.path.join(output, name))
        except FileNotFoundError:
            pass
    for target in targets:
        rel = os.path.relpath(target, output)
        os.makedirs(os.path.dirname(os.path.abspath(target)), exist_ok=True)
        os.replace(os.path.join(staging, rel), target)
    if os.path.exists(os.path.join(output, FAILURES)):
        os.remove(os.path.join(output, FAILURES))  # the earlier run's
    os.replace(os.path.join(staging, MANIFEST), old_manifest)
    shutil.rmtree(staging, ignore_errors=True)


def _done(source: str, target: str) -> bool:
    """A result written (atomically, so whole) after its input changed."""
    return os.path.exists(target) and \
        os.path.getmtime(target) >= os.path.getmtime(source)


def _debug_work(task) -> Tuple[str, Optional[str], Optional[str]]:
    """:func:`precompute_file` that lets the traceback through."""
    precompute_file(*task)
    return task[2], None, None


def run_tasks(tasks, workers: int, quiet: bool, debug: bool, desc: str):
    """Runs ``_work`` over ``tasks`` with
    :func:`tg_intrinsic.parallel.parallel_map`; yields ``(source, reason
    or None, traceback or None)`` in the order of ``tasks``. A worker
    process that dies fails its file and the ones after it (a rerun
    resumes)."""
    from tg_intrinsic.parallel import WorkerDied, parallel_map
    work = _debug_work if debug and (workers == 1 or len(tasks) == 1) \
        else _work
    done = 0
    try:
        for result in parallel_map(work, tasks, workers, desc=desc,
                                   log=not quiet, unit='file',
                                   name_of=lambda _, task: task[2]):
            done += 1
            yield result
    except WorkerDied:
        for task in tasks[done:]:
            yield (task[2], 'its worker process died (out of memory? try '
                   'fewer --workers)', None)


def run(args):
    from tg_intrinsic.io.results import output_lock, output_path
    start = time.perf_counter()
    if args.kind == 'gravo' and args.ratio <= 1:
        raise UsageError(f"--ratio must be greater than 1 (each level keeps "
                         f"about 1/RATIO of the points), got {args.ratio:g}")
    args.output = output_path(args.output)  # a link: written through
    pairs, folder = plan(args.input, args.output)
    with output_lock(args.output, 'OUTPUT'):
        return _precompute(args, pairs, folder, start)


def _precompute(args, pairs, folder: bool, start: float) -> int:
    import tg_intrinsic
    from tg_intrinsic.utils import atomic_write_json, remove_temporaries
    settings = settings_of(args)
    write_to = args.output
    if folder:
        manifest = {'kind': args.kind, 'settings': settings,
                    'format': 'torch.save of a torch_geometric Data '
                    '(tg_intrinsic.data.IntrinsicData); load with '
                    'torch.load(path, weights_only=False)',
                    'input': os.path.abspath(args.input),
                    'tg_intrinsic': tg_intrinsic.__version__}
        write_to = choose_folder(args.output, manifest, args.overwrite,
                                 [target for _, target in pairs])
    elif os.path.exists(args.output) and not args.overwrite:
        raise UsageError(f"OUTPUT '{args.output}' exists; rerun with "
                         f"--overwrite to replace it, or give another name")
    staged = write_to != args.output

    def where(target):
        return os.path.join(write_to, os.path.relpath(target, args.output)) \
            if staged else target
    todo = [(s, t) for s, t in pairs if not folder or not _done(s, where(t))
            or (args.overwrite and not staged)]
    for _, target in todo:
        os.makedirs(os.path.dirname(os.path.abspath(where(target))),
                    exist_ok=True)
    if folder:  # precompute's own folder, locked: no one else writes there
        leftovers = [os.path.relpath(os.path.join(place, name), write_to)
                     for place in sorted({os.path.dirname(where(target))
                                          for _, target in pairs})
                     for name in remove_temporaries(place)]
        if leftovers and not args.quiet:
            print(f"removed {len(leftovers)} temporary file(s) of an "
                  f"interrupted write from {write_to}: "
                  f"{', '.join(leftovers)}")
    tasks = [(args.kind, settings, source, where(target))
             for source, target in todo]
    failures = {}
    for source, reason, trace in [] if not tasks else run_tasks(
            tasks, args.workers, args.quiet, args.debug,
            f'precompute {args.kind}'):
        if reason is not None:
            failures[source] = (reason, trace)
    failures_path = os.path.join(write_to if folder else os.path.dirname(
        os.path.abspath(args.output)), FAILURES)
    seconds = time.perf_counter() - start
    if failures:
        names = [(source, os.path.relpath(source, args.input)
                  if os.path.isdir(args.input) else source)
                 for source, _ in pairs if source in failures]
        if folder:
            atomic_write_json(failures_path, [
                dict(file=name, error=failures[source][0],
                     **({'traceback': failures[source][1]}
                        if failures[source][1] else {}))
                for source, name in names])
        listed = '; '.join(f"{name}: {failures[source][0]}"
                           for source, name in names)
        traces = any(trace for _, trace in failures.values())
        if staged:
            note = (f" (listed in {failures_path}"
                    + (', with the tracebacks' if traces else '')
                    + f"; '{args.output}' still holds the earlier results, "
                    f"untouched: the new ones wait in {write_to} until every "
                    f"file is done; rerun this command to retry the failed "
                    f"ones)")
        elif folder:
            note = (f" (listed in {failures_path}"
                    + (', with the tracebacks' if traces else '')
                    + '; the other files are done, rerun to retry the '
                    'failed ones)')
        else:
            note = ' (rerun with --debug for the traceback)' if traces \
                else ''
        raise UsageError(f"{len(failures)} of {len(pairs)} file(s) failed: "
                         f"{listed}{note}")
    if folder and os.path.exists(failures_path):
        os.remove(failures_path)  # an earlier run's, now all done
    if staged:
        commit_staging(write_to, args.output,
                       [target for _, target in pairs])
    if not args.quiet:
        skipped = len(pairs) - len(todo)
        if not todo:
            print(f"nothing to do: all {skipped} file(s) are already done "
                  f"in {args.output} (--overwrite recomputes them)")
        else:
            print(f"precomputed {args.kind} for {len(todo)} file(s)"
                  + (f" (skipped {skipped} already done)" if skipped else '')
                  + f" into {args.output} in {seconds:.1f} s")
    return 0
