"""Smooths a signal on a mesh or point cloud, (M + alpha S) x = M y with an
optional bi-Laplacian term beta S M^-1 S, or solves the screened Poisson
problem (S + eta M) x = M y, or runs the conformalized mean curvature
flow (M_t + h S_0) p_t+1 = M_t p_t of a mesh, with Gravo MG; S is the cotan
Laplacian of a manifold mesh, else the robust Laplacian (point clouds,
non-manifold meshes, --robust-laplacian), M the lumped masses. Without
--signal, --smooth smooths the vertex positions (implicit fairing).

Writes to --out: result.ply (the surface, with the input signal and the
result as vertex properties 'signal' and 'result', or 'signal_0..' and
'result_0..' for several channels, beside the vertex properties of a PLY
input in their own types: colours, normals, ...; the new ones replace
the input's 'signal*' and 'result*', e.g. of an earlier run. After
fairing or the flow the positions are the new ones, and the input's
normals, which no longer fit them, are left out), result.png (the result
drawn on the surface) and report.json (the problem, the Laplacian, the
hierarchy, the residual of every cycle and the timings)."""
import os
import time
import warnings

from .common import (UsageError, default_of, stage, positive_float,
                     positive_int)

HELP = ('smooth a signal, solve a screened Poisson problem or flow a mesh '
        'with Gravo MG')
EXAMPLE = """examples:
  tg-intrinsic solve bunny.obj --smooth 1e-3 --out runs/fair
      # implicit fairing: smooths the vertex positions
  tg-intrinsic solve bunny.obj --smooth 1e-3 --signal noisy.npy --out out
  tg-intrinsic solve bunny.obj --smooth 1e-4 --bilaplacian 1e-6 \\
      --signal noisy.npy --out out
  tg-intrinsic solve scan.ply --poisson 10 --signal quality --out out
      # 'quality' is a vertex property of scan.ply (a point cloud works)
  tg-intrinsic solve bunny.obj --poisson 1 --signal f.ply:heat --tol 1e-10
  tg-intrinsic solve bunny.obj --conformal-flow 1e-3 --steps 10 --out out
      # conformalized mean curvature flow: a new matrix every step

A signal is a .npy, .txt or .csv file with one row per vertex (one or more
columns), FILE.ply:NAME (vertex property NAME of a PLY file with the same
vertices) or NAME alone (a vertex property of MESH).

Every step runs on the CPU: the Laplacians (scipy, robust-laplacian), the
hierarchy (numba) and the cycles (pyamg's compiled Gauss-Seidel sweeps).
From Python, GravoMG.solve also takes CUDA tensors (its torch backend,
with Chebyshev smoothing)."""


def add_arguments(parser):
    from tg_intrinsic.solvers import conformal_flow, smooth
    from tg_intrinsic.solvers.gravo_mg import CYCLES, METHODS
    parser.add_argument('mesh', metavar='MESH',
                        help='an OBJ, OFF, PLY or STL mesh or point cloud')
    problem = parser.add_mutually_exclusive_group(required=True)
    problem.add_argument('--smooth', type=positive_float, metavar='ALPHA',
                         help='smooth: (M + ALPHA S) x = M y; ALPHA is a '
                         'time step in squared length units of MESH')
    problem.add_argument('--poisson', type=positive_float, metavar='ETA',
                         help='screened Poisson: (S + ETA M) x = M y '
                         '(needs --signal)')
    problem.add_argument('--conformal-flow', type=positive_float,
                         metavar='STEP', help='conformalized mean curvature '
                         'flow of the mesh: (M_t + STEP S_0) p_t+1 = M_t p_t, '
                         '--steps times, keeping the area and centroid; STEP '
                         'is in squared length units of MESH')
    parser.add_argument('--steps', type=positive_int,
                        default=default_of(conformal_flow, 'steps'),
                        help='with --conformal-flow: number of implicit '
                        'steps (default: %(default)s)')
    parser.add_argument('--method', choices=METHODS, default=None,
                        help="'cycles' (V/W/F-cycles) or 'pcg' (conjugate "
                        "gradients preconditioned by one cycle; fewer "
                        "iterations for the bi-Laplacian) (default: "
                        f"{default_of(smooth, 'method')}, "
                        f"{default_of(conformal_flow, 'method')} for the "
                        f"flow)")
    parser.add_argument('--bilaplacian', type=positive_float, default=None,
                        metavar='BETA', help='with --smooth: add BETA S M^-1 '
                        'S (bi-Laplacian smoothing, which keeps more of the '
                        'low frequencies)')
    parser.add_argument('--signal', default=None, metavar='SOURCE',
                        help='the signal y: FILE.npy/.txt/.csv, FILE.ply:NAME '
                        'or a vertex property NAME of MESH (default with '
                        '--smooth: the vertex positions)')
    parser.add_argument('--out', default=None,
                        help='output folder (default: runs/solve_<MESH name>)')
    parser.add_argument('--overwrite', action='store_true',
                        help='write into --out even when it holds files '
                        'this command did not write (they are kept)')
    parser.add_argument('--tol', type=positive_float,
                        default=default_of(smooth, 'tol'),
                        help='relative residual |M y - A x| / |M y| to reach '
                        'in every channel (default: %(default)s, far below '
                        'what a figure or a float32 signal resolves, for a '
                        'few cycles more than 1e-6)')
    parser.add_argument('--max-cycles', type=positive_int,
                        default=default_of(smooth, 'max_iter'),
                        help='most multigrid cycles, or PCG iterations, '
                        'per solve (default: %(default)s)')
    parser.add_argument('--cycle', choices=CYCLES,
                        default=default_of(smooth, 'cycle'),
                        help='multigrid cycle (default: %(default)s)')
    parser.add_argument('--ratio', type=positive_float,
                        default=default_of(smooth, 'ratio'),
                        help='hierarchy: points kept per level are about '
                        '1/RATIO (default: %(default)s)')
    parser.add_argument('--lower-bound', type=positive_int,
                        default=default_of(smooth, 'lower_bound'),
                        help='hierarchy: smallest level size; surfaces with '
                        'fewer points are solved directly (default: '
                        '%(default)s)')
    parser.add_argument('--robust-laplacian', action='store_true',
                        help='use the robust Laplacian (Sharp and Crane '
                        '2020) for a manifold mesh too, instead of the cotan '
                        'Laplacian: it accepts zero-area and very thin '
                        'triangles (point clouds and non-manifold meshes '
                        'always use it)')


def _problem(args):
    """(name, equation, parameters, title) of what is solved."""
    if args.poisson is not None:
        return ('poisson', '(S + eta M) x = M y', {'eta': args.poisson},
                f'screened Poisson (S + {args.poisson:g} M) x = M y')
    if args.conformal_flow is not None:
        h = args.conformal_flow
        return ('conformal flow', '(M_t + h S_0) p_t+1 = M_t p_t',
                {'step': h, 'steps': args.steps},
                f'conformal flow, {args.steps} steps of h = {h:g}')
    alpha, beta = args.smooth, args.bilaplacian
    if beta is None:
        name = 'fairing' if args.signal is None else 'smooth'
        return (name, '(M + alpha S) x = M y', {'alpha': alpha},
                f'{"fairing" if name == "fairing" else "smoothing"} '
                f'(M + {alpha:g} S) x = M y')
    name = 'bilaplacian fairing' if args.signal is None else \
        'bilaplacian smooth'
    return (name, '(M + alpha S + beta S M^-1 S) x = M y',
            {'alpha': alpha, 'beta': beta},
            f'{"fairing" if args.signal is None else "smoothing"} '
            f'(M + {alpha:g} S + {beta:g} S M^-1 S) x = M y')


def run(args):
    import torch
    from torch_geometric.data import Data

    from tg_intrinsic.io import read_signal, read_surface, write_ply
    from tg_intrinsic.io.figures import draw_surface
    from tg_intrinsic.io.mesh import SIGNAL_EXTENSIONS, check_triangle_areas
    from tg_intrinsic.io.results import claim_folder, result_folder
    from tg_intrinsic.solvers import (ConvergenceWarning, GravoMG,
                                      conformal_flow, poisson, smooth)
    from tg_intrinsic.solvers.systems import (combined_info,
                                              uses_robust_laplacian)
    from tg_intrinsic.transforms import GravoHierarchy
    from tg_intrinsic.utils import atomic_write_json

    if args.bilaplacian is not None and args.smooth is None:
        raise UsageError("--bilaplacian adds to --smooth ALPHA; give "
                         "--smooth too")
    if args.poisson is not None and args.signal is None:
        raise UsageError("--poisson needs a right-hand side: give --signal "
                         "SOURCE (a .npy/.txt/.csv file with one row per "
                         "vertex, FILE.ply:NAME, or a vertex property of "
                         "MESH)")
    if args.conformal_flow is not None and args.signal is not None:
        raise UsageError("--conformal-flow moves the mesh itself; leave out "
                         "--signal")
    if args.ratio <= 1:
        raise UsageError(f"--ratio must be greater than 1 (each level keeps "
                         f"about 1/RATIO of the points), got {args.ratio:g}")
    quiet = args.quiet
    out = args.out if args.out is not None else os.path.join(
        'runs', 'solve_' + os.path.splitext(os.path.basename(args.mesh))[0])
    inputs = [args.mesh]
    if args.signal is not None:
        signal_file = args.signal.rpartition(':')[0] \
            if args.signal.rpartition(':')[0].lower().endswith('.ply') \
            else args.signal
        if os.path.splitext(signal_file)[1].lower() in \
                SIGNAL_EXTENSIONS + ('.ply',):
            inputs.append(signal_file)
    # checked before the work, again when the results are put in place
    claim_folder(out, 'solve', args.overwrite, inputs)
    times = {}
    start = time.perf_counter()
    with stage(f"reading {args.mesh}", quiet, times, 'read'):
        pos, face, properties, inverse = read_surface(args.mesh,
                                                      return_inverse=True)
        n = len(pos)
        data = Data(pos=torch.from_numpy(pos))
        if face is not None:
            data.face = torch.from_numpy(face).t().contiguous()
        if face is None:
            laplacian = 'robust (point cloud)'
        elif uses_robust_laplacian(data):
            laplacian = 'robust (non-manifold mesh)'
        elif args.robust_laplacian:
            laplacian = 'robust (--robust-laplacian)'
        else:
            laplacian = 'cotan'
            check_triangle_areas(args.mesh, pos, face, advice=(
                "give --robust-laplacian (the robust Laplacian accepts "
                "them), or delete these faces from the file, e.g. with "
                "trimesh: m = trimesh.load(path, process=False); "
                "m.update_faces(m.nondegenerate_faces()); m.export(path)"))
        y = pos.copy() if args.signal is None else \
            read_signal(args.signal, n, properties, inverse)
    if args.conformal_flow is not None and face is None:
        raise UsageError(f"--conformal-flow needs a triangle mesh, but "
                         f"{args.mesh} is a point cloud (no faces)")
    name, equation, parameters, title = _problem(args)

    with stage(f"building the hierarchy of {n} points", quiet, times,
                'hierarchy'):
        coarsen = GravoHierarchy(ratio=args.ratio,
                                 lower_bound=args.lower_bound)
        solver = GravoMG.from_data(coarsen(data))
    sizes = [n] + [P.shape[1] for P in solver.prolongations]

    channels = y.reshape(n, -1).shape[1]
    with stage(f"solving {equation} ({channels} channel(s))", quiet, times,
                'total_solve'):
        method = args.method or default_of(
            smooth if args.conformal_flow is None else conformal_flow,
            'method')
        options = dict(solver=solver, tol=args.tol, cycle=args.cycle,
                       max_iter=args.max_cycles, method=method,
                       robust=True if args.robust_laplacian else None)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter('always')
            try:
                if args.conformal_flow is not None:
                    steps = []
                    x = conformal_flow(data, args.conformal_flow, args.steps,
                                       callback=lambda t, i: steps.append(i),
                                       **options)[-1]
                    solver.info = combined_info(steps)
                elif args.poisson is not None:
                    x = poisson(data, args.poisson, y=torch.from_numpy(y),
                                **options)
                else:
                    x = smooth(data, args.smooth, beta=args.bilaplacian or 0.0,
                               y=torch.from_numpy(y), **options)
            except ValueError as error:
                raise UsageError(_with_option_names(str(error))) from error
        for warning in caught:  # in the command line's words
            message = warning.message
            if isinstance(message, ConvergenceWarning):
                text = (f"the solve did not converge: "
                        f"{message.reason(_option_setting)}")
            else:
                text = _with_option_names(str(message))
            warnings.warn(text, warning.category)
        x = x.numpy()
    info = solver.info
    times['setup'] = info.setup_time
    times['solve'] = info.solve_time
    # Laplacian, mass and system matrix: the rest of the solve stage.
    times['assembly'] = max(times.pop('total_solve') - info.setup_time
                            - info.solve_time, 0.0)

    fairing = args.signal is None
    new = {'signal': y, 'result': x}
    kept = _kept_properties(properties, new, moved=fairing)
    ply_path = os.path.join(out, 'result.ply')
    png_path = os.path.join(out, 'result.png')
    with result_folder(out, 'solve', args.overwrite, inputs) as staging:
        with stage('writing result.ply and result.png', quiet, times,
                   'write'):
            write_ply(os.path.join(staging, 'result.ply'),
                      x if fairing else pos, face, properties=new,
                      typed_properties=kept)
            values, label, what = _drawn_values(x, y, fairing, args.signal)
            draw_surface(os.path.join(staging, 'result.png'),
                         x if fairing else pos,
                         None if face is None else face.T, values=values,
                         title=f'{title}\n{what}', label=label)
        times['total'] = time.perf_counter() - start
        report = {
            'input': os.path.abspath(args.mesh),
            'vertices': n,
            'faces': int(len(face)) if face is not None else 'point cloud',
            'laplacian': laplacian,
            'problem': name,
            'equation': equation,
            'parameters': parameters,
            'signal': args.signal or 'vertex positions',
            'channels': channels,
            # named as write_ply names them
            'ply_properties': _column_names(new),
            # the input's vertex properties, kept in result.ply
            'input_properties': _column_names(kept),
            'hierarchy': {'ratio': args.ratio,
                          'lower_bound': args.lower_bound,
                          'graph': 'mesh edges' if face is not None else
                          f'k-nearest neighbours (k = {coarsen.k})',
                          'level_sizes': sizes},
            'solver': {'method': method, 'cycle': args.cycle,
                       'tol': args.tol, 'max_cycles': args.max_cycles,
                       'cycles': info.iterations,
                       'final_relative_residual': info.residuals[-1]
                       if info.residuals else None,
                       'residuals': list(info.residuals),
                       'converged': bool(info.converged),
                       'direct': info.direct},
            'seconds': {key: round(float(value), 6)
                        for key, value in times.items()},
            'outputs': {'ply': ply_path, 'png': png_path},
        }
        atomic_write_json(os.path.join(staging, 'report.json'), report)
    if not quiet:
        _summary(report, args.mesh, out)
    return 0


# the library's names of the weights, and the options that set them
OPTION_OF = {"'alpha'": '--smooth', "'beta'": '--bilaplacian',
             "'eta'": '--poisson', "'step'": '--conformal-flow'}
# the solver's arguments that a ConvergenceWarning names, and the options
# that set them
SETTING_OF = {'max_iter': '--max-cycles', 'tol': '--tol',
              'method': '--method'}
# vertex properties that describe the positions, not kept once they move
NORMALS = ('nx', 'ny', 'nz')


def _option_setting(name: str, value=None) -> str:
    """A solver argument in the command line's words (the wording that
    :meth:`ConvergenceWarning.reason` asks for): ``--max-cycles 5``."""
    option = SETTING_OF[name]
    if value is None:
        return option
    return f'{option} {value:g}' if isinstance(value, float) else \
        f'{option} {value}'


def _column_names(properties: dict) -> list:
    """The PLY vertex properties that write_ply makes of ``properties``:
    ``name``, or ``name_0`` to ``name_{C-1}`` for several columns."""
    names = []
    for name, values in properties.items():
        columns = 1 if values.ndim == 1 else values.shape[1]
        names += [name] if columns == 1 else \
            [f'{name}_{k}' for k in range(columns)]
    return names


def _kept_properties(properties: dict, new: dict, moved: bool) -> dict:
    """The input's vertex properties that result.ply keeps: all but those
    the ``new`` ones replace (``NAME`` and its columns ``NAME_0``, ... for
    every new ``NAME``, e.g. of an earlier result.ply) and, when the
    positions ``moved``, the normals."""
    import re
    replaced = re.compile('|'.join(f'{re.escape(name)}(_[0-9]+)?'
                                   for name in new))
    return {name: values for name, values in properties.items()
            if not replaced.fullmatch(name)
            and not (moved and name in NORMALS)}


def _with_option_names(message: str) -> str:
    """A library message in the command line's words."""
    for name, option in OPTION_OF.items():
        message = message.replace(f'{name} = ', f'{option} ').replace(
            name, option)
    return message


def _drawn_values(x, y, fairing: bool, signal):
    """(per-vertex values, colour bar label, what they are) to draw."""
    import numpy as np
    if fairing:
        return (np.linalg.norm(x - y, axis=1), 'distance moved (mesh units)',
                'colour: distance each vertex moved')
    name = os.path.basename(signal)
    if x.ndim == 2 and x.shape[1] == 1:
        x = x[:, 0]
    if x.ndim == 1:
        return x, f'result ({name})', f'colour: the result for {name}'
    if x.shape[1] <= 3:
        return (np.linalg.norm(x, axis=1), f'|result| ({name})',
                f'colour: vector norm of the {x.shape[1]} result channels')
    return (x[:, 0], f'result channel 0 ({name})',
            f'colour: channel 0 of {x.shape[1]}')


def _summary(report: dict, mesh: str, out: str):
    solver = report['solver']
    faces = report['faces']
    shape = 'point cloud' if faces == 'point cloud' else f'{faces} faces'
    weights = ', '.join(f'{k}={v:g}' for k, v in
                        report['parameters'].items())
    print(f"solved {report['equation']} ({weights}) on {mesh}: "
          f"{report['vertices']} vertices, {shape}, {report['laplacian']} "
          f"Laplacian")
    levels = ' -> '.join(str(s) for s in report['hierarchy']['level_sizes'])
    seconds = report['seconds']
    if solver['direct']:
        how = f"solved directly ({solver['direct']})"
    else:
        state = 'converged' if solver['converged'] else \
            'NOT converged (raise --max-cycles or --tol)'
        if solver['method'] == 'pcg':
            how = (f"{solver['cycles']} PCG iterations (one "
                   f"{solver['cycle']}-cycle each)")
        else:
            how = f"{solver['cycles']} {solver['cycle']}-cycles"
        if report['problem'] == 'conformal flow':
            how += f" over {report['parameters']['steps']} steps, each"
        how += (f" to relative residual "
                f"{solver['final_relative_residual']:.2g}, {state}")
    print(f"  hierarchy {levels} ({seconds['hierarchy']:.2f} s); {how}; "
          f"setup {seconds['setup']:.2f} s, solve {seconds['solve']:.2f} s")
    print(f"  wrote {os.path.join(out, 'result.ply')}, result.png and "
          f"report.json")
