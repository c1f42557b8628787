"""Recovers a spatially varying BRDF (base colour, metallic, roughness) and
its uncertainty (the estimated standard deviation of the roughness of the
final fit, and the normalised entropy of the power-spectrum likelihood)
on every point of a surface from calibrated linear HDR photographs under a
known environment map, with frequency-domain SVBRDF recovery (Wiersma et
al., SIGGRAPH 2025), as FrequencySVBRDF.recover runs it: ProjectViews,
FitSphericalHarmonics and SpectralUncertainty, then by default the
refinement against the full integral of the light whenever the scene
allows it (a mesh for the visibility, or --visibility horizon for a convex
point cloud), else the spherical-harmonic fit (--refine 0 asks for it
alone). --write-example DIR writes a small synthetic scene folder (with
its ground truth) to start from.

Writes to --out: maps.npz (base_color [N, 3], metallic, roughness,
entropy, roughness_std [N]), one PLY per map (the surface with the map as
a vertex property: base_color_0..2 (linear), metallic, roughness, entropy,
roughness_std; as vertex
colours: the base colour sRGB-encoded, the others through the colormap of
their figure; normals as nx ny nz), one PNG per map drawn on the surface
with a colour bar, with --texture N the maps as N x N textures
(*_texture.png) and svbrdf.glb (glTF 2.0 with the PBR material), and
report.json (points, views, observations per point, the steps that ran
and their seconds, losses, mean uncertainties, and errors against
ground_truth.npz when the scene folder has one). The files appear in
--out together when all are written, replacing those of an earlier svbrdf
run there: a failed run leaves --out as it was. --out may not hold the
scene, and a folder holding files svbrdf did not write needs --overwrite
(the same for --write-example DIR)."""
import math
import os
import sys
import time

from .common import (UsageError, default_of, stage, nonnegative_float,
                     nonnegative_int, positive_float, positive_int)

HELP = 'recover SVBRDF maps and their uncertainty from HDR photographs'

SPECULAR_MODELS = ('eq5.11', 'split_sum')
VISIBILITY = ('auto', 'geometry', 'horizon')
# a 16k x 16k texture is 1 GB per map: larger is a typing mistake
MAX_TEXTURE = 8192
# the synthetic example: an icosphere of 642 vertices seen by 24 cameras
EXAMPLE_SUBDIVISIONS = 3
EXAMPLE_VIEWS = 24
EXAMPLE_IMAGE_SIZE = 96


def _indent(text: str) -> str:
    return '\n'.join('  ' + line if line else '' for line in text.split('\n'))


def _scene_format() -> str:
    from tg_intrinsic.io.scene import FORMAT
    return FORMAT


EXAMPLE = f"""examples:
  tg-intrinsic svbrdf --write-example scene     # a synthetic scene to start
  tg-intrinsic svbrdf scene --out runs/svbrdf   # maps, PLYs, PNGs, report
  tg-intrinsic svbrdf scene --texture 512       # + textures and svbrdf.glb
  tg-intrinsic svbrdf scene --refine 0 --solver adam   # the paper's method
  tg-intrinsic svbrdf my_capture --metallic 1 --tv-weight 0.01 --device cuda
  tg-intrinsic svbrdf colmap_project --geometry mesh.ply --envmap sky.exr \
      --exposure 0.5 --up y     # COLMAP + JPEGs, y-up world
  tg-intrinsic svbrdf --write-example cap --format nerfstudio --ldr

captures (CAPTURE), recognised in this order:
  SCENE/cameras.json          the native scene folder (below)
  Stanford-ORB                ROOT/blender_HDR/<scene> or ROOT/<scene>
  transforms.json             NeRF/Blender (camera_angle_x, OpenGL poses)
                              or nerfstudio (fl_x fl_y cx cy w h, k1 k2 p1
                              p2, mask_path); also transforms_train.json
  COLMAP model                cameras/images/points3D .txt or .bin, in
                              CAPTURE, CAPTURE/sparse/0 or CAPTURE/sparse,
                              photographs in CAPTURE/images/, masks in
                              CAPTURE/masks/ (optional)
  Photographs: linear HDR (.exr, .hdr) or 8-bit (PNG, JPEG: --exposure).
  Pixel centres: COLMAP's, NeRF's and nerfstudio's cx, cy are used as
  they are (centres at half-integers); NeRF's principal point is (W/2,
  H/2). Without --geometry/--envmap the format's files are used, else the
  one mesh and the one .exr/.hdr file in the capture folder.

the scene folder (native format):
{_indent(_scene_format())}"""


def _degrees(text: str) -> float:
    """argparse type of --envmap-rotation: a finite number of degrees."""
    import argparse
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of degrees, got "
                                         f"{text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be finite, got {text!r}")
    return value


def _unit_float(text: str) -> float:
    """argparse type: a number in [0, 1]."""
    import argparse
    value = nonnegative_float(text)
    if value > 1:
        raise argparse.ArgumentTypeError(f"must lie in [0, 1], got {text!r}")
    return value


def _texture_size(text: str) -> int:
    """argparse type of --texture: a side of 8 to 8192 texels."""
    import argparse
    value = positive_int(text)
    if not 8 <= value <= MAX_TEXTURE:
        raise argparse.ArgumentTypeError(
            f"must lie in [8, {MAX_TEXTURE}] texels, got {text!r}")
    return value


def _l_max_type(samples: int):
    """argparse type of --l-max: a degree whose (L + 1)^2 coefficients the
    ``samples`` light directions per point can fit, 4 per coefficient (as
    FitSphericalHarmonics requires)."""
    import argparse
    largest = math.isqrt(samples // 4) - 1

    def l_max(text: str) -> int:
        value = positive_int(text)
        if value > largest:
            raise argparse.ArgumentTypeError(
                f"must be at most {largest}, got {text!r}: the light at each "
                f"point is sampled in {samples} directions, and degree L has "
                f"(L + 1)^2 coefficients that need 4 samples each")
        return value
    l_max.largest = largest
    return l_max


def add_arguments(parser):
    from tg_intrinsic.nn import FrequencySVBRDF
    from tg_intrinsic.transforms import FitSphericalHarmonics
    from tg_intrinsic.nn.frequency_svbrdf import (DEFAULT_L_MAX,
                                                  DEFAULT_STEPS,
                                                  REFINE_STEPS, SOLVERS)
    tv_weight = default_of(FrequencySVBRDF.recover, 'tv_weight')
    l_max_type = _l_max_type(default_of(FitSphericalHarmonics.__init__,
                                        'num_light_samples'))
    parser.add_argument('scene', nargs='?', metavar='CAPTURE',
                        help='the capture: a scene folder (format below), a '
                        'COLMAP model with images/, a transforms.json '
                        '(NeRF/Blender or nerfstudio) or a Stanford-ORB '
                        'scene; the format is recognised (--format)')
    parser.add_argument('--out', default=None, metavar='DIR',
                        help='output folder (default: runs/svbrdf_<CAPTURE'
                        ' name>)')
    _add_capture_arguments(parser)
    parser.add_argument('--overwrite', action='store_true',
                        help='write into --out (or --write-example DIR) even '
                        'when it holds files that svbrdf did not write: '
                        'those are kept, files of the same name replaced')
    parser.add_argument('--solver', choices=SOLVERS, default=None,
                        help='solver of the spherical-harmonic fit: lm, '
                        'Levenberg-Marquardt per point (the default); adam, '
                        'gradient descent on all points (the original\'s). '
                        'Before a refinement the fit runs only when '
                        '--solver or --steps is given: the refinement '
                        'starts from the spectrum on its own')
    parser.add_argument('--steps', type=nonnegative_int, default=None,
                        metavar='N',
                        help='Adam steps, or Levenberg-Marquardt iterations '
                        'per round; 0 keeps the spectrum grid-search start '
                        '(default: ' + ', '.join(
                            f'{n} for {s}' for s, n in DEFAULT_STEPS.items())
                        + ', the library\'s)')
    parser.add_argument('--l-max', type=l_max_type, default=None,
                        metavar='L',
                        help=f'spherical-harmonic degree of the light and '
                        f'the observations, 1 to {l_max_type.largest} '
                        f'(default: ' + ', '.join(
                            f'{n} for {m}' for m, n in DEFAULT_L_MAX.items())
                        + ')')
    parser.add_argument('--specular-model', choices=SPECULAR_MODELS,
                        default=SPECULAR_MODELS[0],
                        help='eq5.11: the paper\'s model; split_sum: '
                        'prefiltered light times the GGX directional albedo,'
                        ' more accurate (default: eq5.11)')
    parser.add_argument('--metallic', type=_unit_float, default=None,
                        metavar='M', help='hold metallic at M (1 for a '
                        'metal, 0 for a dielectric) instead of fitting it, '
                        'when the material class is known')
    parser.add_argument('--tv-weight', type=nonnegative_float,
                        default=tv_weight, metavar='W',
                        help=f'total-variation weight over the surface '
                        f'graph, smoothing the maps (default: '
                        f'{tv_weight:g})')
    parser.add_argument('--refine', type=nonnegative_int, default=None,
                        metavar='N',
                        help=f'refine the maps against the full integral of '
                        f'the environment light with N Levenberg-Marquardt '
                        f'iterations per round (the lowest error); 0: the '
                        f'spherical-harmonic recovery alone, the paper\'s '
                        f'(default: {REFINE_STEPS} when the scene has a mesh '
                        f'or --visibility horizon is given, else 0)')
    parser.add_argument('--visibility', choices=VISIBILITY,
                        default=VISIBILITY[0],
                        help='occlusion of the light in the refinement: '
                        'geometry (rays against the mesh), horizon (every '
                        'direction above the tangent plane: right for '
                        'convex objects, and what lets a point cloud be '
                        'refined) or auto (geometry when the scene has a '
                        'mesh) (default: auto)')
    parser.add_argument('--texture', type=_texture_size, default=None,
                        metavar='N',
                        help='also write the maps as N x N textures on the '
                        'mesh\'s UVs (an atlas is made with xatlas when it '
                        'has none): base_color/metallic/roughness/'
                        'entropy/roughness_std_texture.png and svbrdf.glb, '
                        'a glTF 2.0 '
                        'binary with the PBR material that Blender and glTF '
                        'viewers open (the thesis: 512)')
    parser.add_argument('--device', default='cpu',
                        help='cpu, cuda, cuda:N or auto (cuda when there is '
                        'one) (default: cpu)')
    parser.add_argument('--dtype', choices=('float64', 'float32'),
                        default='float64', help='precision of the '
                        'computation; float32 halves the memory '
                        '(default: float64)')
    _add_example_arguments(parser)


def _add_capture_arguments(parser):
    """The options a capture format has no place for."""
    from tg_intrinsic.io.capture import CAPTURE_FORMATS
    from tg_intrinsic.io.capture_writer import WRITE_FORMATS
    from tg_intrinsic.io.capture_views import UP_AXES
    capture = parser.add_argument_group(
        'captures', 'what a capture format has no place for')
    capture.add_argument('--format', default=None, choices=sorted(
        set(CAPTURE_FORMATS) | set(WRITE_FORMATS)),
        help='the capture\'s format (default: recognised from the folder);'
        ' with --write-example, the format to write (default: native)')
    capture.add_argument('--geometry', default=None, metavar='MESH',
                         help='the surface (OBJ, OFF, PLY, STL), in the '
                         'cameras\' world (default: the format\'s, else '
                         'the one mesh file in the capture folder)')
    capture.add_argument('--envmap', default=None, metavar='MAP',
                         help='the lighting, an equirectangular .exr/.hdr '
                         '(default: the format\'s, else the one such file '
                         'in the capture folder)')
    capture.add_argument('--exposure', type=positive_float, default=None,
                         metavar='S', help='8-bit photographs: decoded '
                         'values are S times the radiance of the '
                         'environment map\'s units (required for LDR '
                         'photographs; EXIF exposures, where every '
                         'photograph has one, scale each relative to the '
                         'first)')
    capture.add_argument('--gamma', type=positive_float, default=None,
                         metavar='G', help='decode 8-bit photographs as '
                         'value^G instead of the sRGB curve')
    capture.add_argument('--envmap-rotation', type=_degrees, default=0.0,
                         metavar='DEGREES', help='turn the lighting about '
                         'world up (default: 0)')
    capture.add_argument('--show-cameras', action='store_true',
                         help='write only cameras.png (the cameras around '
                         'the surface, seen from three sides) to --out and '
                         'stop: a quick look at whether a capture was read '
                         'right; a recovery writes it too')
    capture.add_argument('--up', choices=UP_AXES, default='z',
                         help='the up axis of the capture\'s world; y is '
                         'turned to the library\'s z (default: z)')


def _add_example_arguments(parser):
    """The options of --write-example."""
    example = parser.add_argument_group(
        'synthetic example', 'write a scene folder instead of reading one')
    example.add_argument('--write-example', default=None, metavar='DIR',
                         help='write a synthetic scene (svbrdf_scene: '
                         'metals under a sun and sky) with '
                         'ground_truth.npz into DIR and stop')
    example.add_argument('--example-views', type=positive_int, default=None,
                         metavar='N', help=f'cameras of the example '
                         f'(default: {EXAMPLE_VIEWS})')
    example.add_argument('--example-image-size', type=positive_int,
                         default=None, metavar='PIXELS',
                         help=f'side of its square photographs (default: '
                         f'{EXAMPLE_IMAGE_SIZE})')
    example.add_argument('--example-subdivisions', type=nonnegative_int,
                         default=None, metavar='S', help=f'icosphere '
                         f'subdivisions, 10 * 4^S + 2 vertices (default: '
                         f'{EXAMPLE_SUBDIVISIONS}: 642)')
    example.add_argument('--ldr', action='store_true',
                         help='write 8-bit sRGB PNG photographs (not with '
                         '--format native)')
    example.add_argument('--seed', type=nonnegative_int, default=0,
                         help='of the example\'s materials and sun '
                         '(default: 0)')


def run(args):
    example_options = (args.example_views, args.example_image_size,
                       args.example_subdivisions)
    if args.write_example is not None:
        if args.scene is not None:
            raise UsageError("give either CAPTURE (to recover maps) or "
                             "--write-example DIR (to write a scene), not "
                             "both")
        # options of the recovery would be ignored without a word
        given = [option for option, value in (
            ('--out', args.out), ('--steps', args.steps),
            ('--l-max', args.l_max), ('--metallic', args.metallic),
            ('--solver', args.solver), ('--refine', args.refine),
            ('--texture', args.texture), ('--geometry', args.geometry),
            ('--envmap', args.envmap), ('--exposure', args.exposure),
            ('--gamma', args.gamma),
            ('--envmap-rotation', args.envmap_rotation or None),
            ('--up', None if args.up == 'z' else args.up),
            ('--show-cameras', args.show_cameras or None),
            ('--visibility', None if args.visibility == VISIBILITY[0]
             else args.visibility)) if value is not None]
        if given:
            one = len(given) == 1
            raise UsageError(
                f"{', '.join(given)} {'is' if one else 'are'} not used with "
                f"--write-example DIR, which writes the scene into DIR and "
                f"stops; drop {'it' if one else 'them'} and recover its maps "
                f"afterwards with 'tg-intrinsic svbrdf DIR --out OUT'")
        return write_example(args)
    if any(option is not None for option in example_options) or args.ldr:
        raise UsageError("--example-views, --example-image-size, "
                         "--example-subdivisions and --ldr only go with "
                         "--write-example DIR")
    if args.format == 'colmap-bin':
        args.format = 'colmap'  # read: text and binary models alike
    if args.scene is None:
        raise UsageError("give a CAPTURE (a scene folder, a COLMAP model, a "
                         "transforms.json or a Stanford-ORB scene; see "
                         "'tg-intrinsic svbrdf --help') or --write-example "
                         "DIR")
    return recover(args)


# ------------------------------------------------------------------ example
def write_example(args) -> int:
    """Writes the synthetic scene of ``--write-example`` in ``--format``."""
    import numpy as np
    from tg_intrinsic.datasets import svbrdf_scene
    from tg_intrinsic.io import scene_summary
    from tg_intrinsic.io.capture_writer import write_capture
    from tg_intrinsic.io.results import result_folder
    from tg_intrinsic.io.scene import FORMAT, GROUND_TRUTH_FILE
    from tg_intrinsic.utils import atomic_write

    folder = args.write_example
    form = args.format or 'native'
    if args.ldr and form == 'native':
        raise UsageError("--ldr writes 8-bit photographs, which a native "
                         "scene folder does not hold; add --format colmap, "
                         "nerf, nerfstudio or orb")
    views = args.example_views or EXAMPLE_VIEWS
    size = args.example_image_size or EXAMPLE_IMAGE_SIZE
    subdivisions = EXAMPLE_SUBDIVISIONS if args.example_subdivisions is None \
        else args.example_subdivisions
    # an earlier example is replaced whole; a user's files (a capture's
    # cameras.json, photographs) only with --overwrite
    with result_folder(folder, 'svbrdf-example', args.overwrite,
                       option='--write-example') as staging:
        if not args.quiet:
            print(f"rendering a synthetic scene ({views} views of {size} x "
                  f"{size}) ...", file=sys.stderr, flush=True)
        data = svbrdf_scene('sphere', num_views=views,
                            image_size=(size, size), materials='metals',
                            seed=args.seed, resolution=subdivisions)
        written = write_capture(staging, data, form, ldr=args.ldr)
        capture = os.path.relpath(written['capture'], staging)
        truth = {name: getattr(data, name).detach().cpu().numpy()
                 for name in ('base_color', 'metallic', 'roughness', 'pos')}
        atomic_write(os.path.join(written['capture'], GROUND_TRUTH_FILE),
                     lambda f: np.savez(f, **truth), 'wb')
        path = os.path.normpath(os.path.join(folder, capture))
        command = _recover_command(path, form, written['exposure'])
        readme = ('A synthetic scene written by "tg-intrinsic svbrdf '
                  '--write-example" (tg_intrinsic.datasets.svbrdf_scene: '
                  f'metals under a sun and sky, seed {args.seed}), in the '
                  f'{form} format'
                  f'{" with 8-bit photographs" if args.ldr else ""}.\n'
                  f'Recover its maps with: {command}\n'
                  + (f'\n{FORMAT}\n' if form == 'native' else ''))
        atomic_write(os.path.join(staging, 'README.txt'),
                     lambda f: f.write(readme), 'w')
    if not args.quiet:
        print(f"wrote {folder}: {scene_summary(data)}, in the {form} "
              f"format, with {GROUND_TRUTH_FILE}\nnext: {command}")
    return 0


def _recover_command(path: str, form: str, exposure) -> str:
    exposure = '' if exposure is None else f' --exposure {exposure:.9g}'
    return f"tg-intrinsic svbrdf {path}{exposure} --out OUT"


# ------------------------------------------------------------------ recovery
def recover(args) -> int:
    """Reads the scene, recovers the maps and writes the outputs."""
    import torch

    from tg_intrinsic.devices import resolve_device
    from tg_intrinsic.io.capture import read_capture
    from tg_intrinsic.io.results import check_output_path, result_folder
    from tg_intrinsic.io.scene import GROUND_TRUTH_FILE, scene_files

    device = resolve_device(args.device, '--device')
    dtype = getattr(torch, args.dtype)
    scene = args.scene
    out = args.out if args.out is not None else os.path.join(
        'runs', 'svbrdf_' + os.path.basename(os.path.normpath(
            os.path.abspath(scene))))
    check_output_path(out, [scene], '--out')  # before any work
    seconds = {}
    start = time.perf_counter()
    # read without a progress line: a bad scene is reported on one line
    data = read_capture(scene, args.format, dtype=dtype,
                        geometry=args.geometry, envmap=args.envmap,
                        exposure=args.exposure, gamma=args.gamma,
                        envmap_rotation=args.envmap_rotation, up=args.up)
    capture = data.capture_info
    del data.capture_info
    truth_path = os.path.join(capture['folder'], GROUND_TRUTH_FILE)
    truth = _read_ground_truth(truth_path, data.pos) \
        if os.path.lexists(truth_path) else None
    inputs = [scene, truth_path, capture['folder']] + (
        scene_files(capture['folder']) if capture['format'] == 'native'
        else [capture['geometry'], capture['envmap']]
        + capture.get('lightings', []))
    seconds['read'] = round(time.perf_counter() - start, 3)
    if args.texture is not None:
        _check_texture_inputs(data)
    # every file written goes to a staging folder, put in place only when
    # all are written; --out may not hold the scene (--out SCENE/images)
    with result_folder(out, 'svbrdf', args.overwrite,
                       inputs=inputs) as staging:
        figure = _draw_cameras(staging, scene, data, capture)
        if args.show_cameras:
            from tg_intrinsic.utils import atomic_write_json
            atomic_write_json(os.path.join(staging, 'report.json'), {
                'scene': os.path.abspath(scene), 'capture': capture,
                'files': ['cameras.png', 'report.json']})
        else:
            report = _recover(args, data, truth, device, seconds, start,
                              staging, capture)
    if args.show_cameras:
        print(f"wrote {os.path.join(out, figure)}: the cameras around the "
              f"surface ({capture['format']} capture)")
    elif not args.quiet:
        _print_summary(out, report)
    return 0


def _draw_cameras(out: str, scene: str, data, capture: dict) -> str:
    """cameras.png: the capture's cameras around its surface."""
    from tg_intrinsic.io.figures import draw_cameras
    name = os.path.basename(os.path.normpath(os.path.abspath(scene)))
    draw_cameras(os.path.join(out, 'cameras.png'), data.pos,
                 data.intrinsics, data.extrinsics,
                 tuple(data.images.shape[1:3]),
                 f"the cameras of {name} ({capture['format']} capture)")
    return 'cameras.png'


def _recover(args, data, truth, device, seconds, start, out,
             capture: dict) -> dict:
    """Recovers the maps of the scene read into ``data`` and writes every
    output into ``out`` (the staging folder); returns the report."""
    import numpy as np

    import tg_intrinsic
    from tg_intrinsic.io import scene_summary
    from tg_intrinsic.nn import FrequencySVBRDF
    from tg_intrinsic.utils import atomic_write_json

    scene = args.scene
    if not args.quiet:
        print(f"read {scene} ({capture['format']} capture): "
              f"{scene_summary(data)}", file=sys.stderr, flush=True)
    model = FrequencySVBRDF(data.num_nodes,
                            specular_model=args.specular_model).to(device)
    refine = {None: 'auto', 0: False}.get(args.refine, True)
    result, data = model.recover(
        data.to(device), refine=refine, visibility=args.visibility,
        solver=args.solver, steps=args.steps,
        **({} if refine is not True else {'refine_steps': args.refine}),
        l_max=args.l_max, tv_weight=args.tv_weight, metallic=args.metallic,
        log=None if args.quiet else lambda line: print(
            line, file=sys.stderr, flush=True),
        progress=not args.quiet)
    pipeline = result.pipeline
    fit, refine = pipeline['fit'], pipeline['refine']
    seconds.update(pipeline['seconds'])
    with stage('writing', args.quiet, seconds, 'write'):
        maps = result.maps()
        files = _write_outputs(out, data, result, maps,
                               os.path.basename(os.path.normpath(
                                   os.path.abspath(scene))))
        texture = None
        if args.texture is not None:
            from tg_intrinsic.io.gltf import write_textured_model
            texture = write_textured_model(
                out, data.pos, data.face, maps, args.texture,
                getattr(data, 'face_uv', None), data.normal)
            files += texture.pop('files')
    seconds['total'] = round(time.perf_counter() - start, 3)

    seen = data.obs_mask.sum(1).cpu().double()
    face = getattr(data, 'face', None)
    report = {
        'scene': os.path.abspath(scene),
        'capture': capture,
        'points': int(data.num_nodes),
        'triangles': None if face is None else int(face.size(1)),
        'views': int(data.images.size(0)),
        'image_size': list(data.images.shape[1:3]),
        'envmap_size': list((data.envmap if 'envmap' in data
                             else data.envmaps[0]).shape[:2]),
        'lightings': 1 if 'envmap' in data else int(data.envmaps.size(0)),
        'observations_per_point': {
            'min': int(seen.min()), 'median': float(seen.median()),
            'mean': round(float(seen.mean()), 3), 'max': int(seen.max()),
            'unseen_points': int((seen == 0).sum()),
            # seen by a camera, but on a pixel left out (capture's
            # pixels_left_out says why)
            'left_out': int(data.obs_left_out.sum())
            if 'obs_left_out' in data else 0},
        'pipeline': {
            'steps': list(pipeline['seconds']),
            'fit': pipeline['fit'], 'refine': pipeline['refine'],
            'not_refined_because': pipeline['not_refined_because']},
        # what ran, the defaults resolved
        'options': {'solver': fit and fit['solver'],
                    'steps': fit and fit['steps'],
                    'l_max': pipeline['l_max'],
                    'specular_model': args.specular_model,
                    'metallic': args.metallic, 'tv_weight': args.tv_weight,
                    'refine': refine['steps'] if refine else 0,
                    'visibility': refine and refine['visibility'],
                    'device': str(device), 'dtype': args.dtype},
        'seconds': seconds,
        'peak_memory_gib': _peak_memory_gib(),
        'loss': pipeline['loss'],
        'texture': texture,
        'mean_entropy': float(np.mean(maps['entropy'])),
        'mean_roughness_std': float(np.mean(maps['roughness_std'])),
        'ground_truth': None if truth is None else _errors(maps, truth),
        'files': sorted([os.path.basename(f) for f in files]
                        + ['cameras.png']) + ['report.json'],
        'tg_intrinsic': tg_intrinsic.__version__,
    }
    atomic_write_json(os.path.join(out, 'report.json'), report)
    return report


def _peak_memory_gib() -> float:
    """The most memory this process has held (resident), in GiB."""
    import resource
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    # kilobytes on Linux, bytes on macOS
    return round(peak / (2 ** 30 if sys.platform == 'darwin' else 2 ** 20),
                 3)


def _check_texture_inputs(data):
    """--texture needs a mesh, and UVs or xatlas to make them: said
    before any work."""
    if getattr(data, 'face', None) is None:
        raise UsageError("--texture needs a mesh to put the textures on; "
                         "the scene's geometry is a point cloud")
    if getattr(data, 'face_uv', None) is None:
        try:
            import xatlas  # noqa: F401
        except ImportError:
            raise UsageError("--texture on a mesh without UVs needs the "
                             "xatlas package to make an atlas: pip install "
                             "xatlas, or give the mesh UVs (OBJ vt, PLY s "
                             "t)") from None


def _read_ground_truth(path: str, pos) -> dict:
    import numpy as np
    num_points = pos.size(0)
    if os.path.isdir(path):
        raise ValueError(f"'{path}' is a folder, not a file: the optional "
                         f"ground truth is a .npz file of base_color [N, 3],"
                         f" roughness [N] and metallic [N]; move or rename "
                         f"the folder")
    truth, reason = _load_npz(path)
    if reason is not None:
        raise ValueError(f"'{path}' is not a readable .npz of the ground "
                         f"truth ({reason}); delete or repair it")
    shapes = {'base_color': (num_points, 3), 'roughness': (num_points, ),
              'metallic': (num_points, )}
    for name, shape in shapes.items():
        if name not in truth:
            if name == 'metallic':
                continue
            raise ValueError(f"'{path}' has no '{name}'; it needs "
                             f"base_color [N, 3] and roughness [N] "
                             f"(metallic [N] optional)")
        if truth[name].shape != shape:
            raise ValueError(f"'{path}': '{name}' has shape "
                             f"{list(truth[name].shape)} but the geometry "
                             f"has {num_points} points, so it must be "
                             f"{list(shape)}")
        if not np.isfinite(truth[name]).all():
            raise ValueError(f"'{path}': '{name}' holds NaN or infinite "
                             f"values")
    if 'pos' in truth:  # the same points in the same order
        pos = pos.detach().cpu().double().numpy()
        scale = float(np.abs(pos).max()) or 1.0
        if truth['pos'].shape != pos.shape or not np.allclose(
                truth['pos'], pos, rtol=0, atol=1e-5 * scale):
            raise ValueError(f"'{path}': its 'pos' are not the points of the"
                             f" geometry file (another mesh, or reordered "
                             f"vertices), so its maps cannot be compared")
    return truth


def _load_npz(path: str):
    """The arrays of numbers in a .npz file and :obj:`None`, or
    :obj:`None` and why they cannot be read."""
    import zipfile
    import numpy as np
    try:
        archive = np.load(path, allow_pickle=False)
    except EOFError:
        return None, 'the file is empty'
    except ValueError as error:
        return None, _numpy_problem(error, '.npz file')
    except zipfile.BadZipFile as error:
        return None, f'a damaged archive: {error}'
    except OSError as error:
        return None, error.strerror or str(error)
    if not isinstance(archive, np.lib.npyio.NpzFile):
        return None, 'one .npy array, not a .npz archive of named maps'
    truth = {}
    with archive:
        for name in archive.files:
            try:
                truth[name] = archive[name]
            except ValueError as error:
                return None, f"its '{name}' cannot be read: " + \
                    _numpy_problem(error, '.npy array')
            except (EOFError, OSError, zipfile.BadZipFile) as error:
                return None, f"its '{name}' is damaged: {error}"
            if not isinstance(truth[name], np.ndarray):  # raw bytes
                return None, f"its '{name}' is not a .npy array"
            if truth[name].dtype.kind not in 'biuf':
                return None, f"its '{name}' holds {truth[name].dtype}, " \
                    f"not numbers"
    return truth, None


def _numpy_problem(error: ValueError, what: str) -> str:
    """numpy's reason for not loading a file, without its advice to load
    pickles (which would run code from the file)."""
    if 'pickled' in str(error):
        return f'it is not a NumPy {what}'
    if 'Object arrays' in str(error):
        return 'it holds Python objects, not numbers'
    return str(error).rstrip('.')


def _errors(maps: dict, truth: dict) -> dict:
    """Errors of the recovered maps against the ground truth, and how well
    each uncertainty ranks the points by their roughness error."""
    import numpy as np
    from scipy.stats import spearmanr
    error = np.abs(maps['roughness'] - truth['roughness'])
    out = {
        'roughness_mae': float(error.mean()),
        'base_color_rmse': float(np.sqrt(np.mean(
            (maps['base_color'] - truth['base_color']) ** 2))),
    }
    if 'metallic' in truth:
        out['metallic_mae'] = float(np.abs(maps['metallic']
                                           - truth['metallic']).mean())
    for name in ('roughness_std', 'entropy'):
        rho = float('nan')
        if np.ptp(maps[name]) > 0 and np.ptp(error) > 0:
            rho = float(spearmanr(maps[name], error).statistic)
        out[f'{name}_roughness_error_spearman'] = None if np.isnan(rho) \
            else rho
    return out


def _write_outputs(out: str, data, result, maps: dict, name: str) -> list:
    """maps.npz, a PLY and a PNG per map; returns the written paths."""
    import matplotlib
    import numpy as np
    from tg_intrinsic.io import write_ply
    from tg_intrinsic.io.figures import draw_surface
    from tg_intrinsic.io.gltf import srgb_encode
    from tg_intrinsic.nn.svbrdf_result import MAP_INFO, scaled_to_range

    pos = data.pos.detach().cpu().double().numpy()
    normal = data.normal.detach().cpu().double().numpy()
    face = getattr(data, 'face', None)
    face = None if face is None else face.detach().cpu().numpy()
    files = [result.save_npz(os.path.join(out, 'maps.npz'))]
    normals = {k: normal[:, i] for i, k in enumerate(('nx', 'ny', 'nz'))}
    points = f"{len(pos)} {'vertices' if face is not None else 'points'}"
    for key in MAP_INFO:
        value = np.asarray(maps[key], dtype=np.float64)
        info = MAP_INFO[key]
        if value.ndim == 2:  # the base colour is its own colour
            colors = srgb_encode(value)
        else:
            colormap = matplotlib.colormaps[info['cmap']]
            colors = colormap(scaled_to_range(key, value))[:, :3]
        files.append(write_ply(os.path.join(out, f'{key}.ply'), pos,
                               None if face is None else face.T,
                               {key: value, **normals}, colors=colors))
        title = f"{info['title']} recovered on {name} ({points})"
        if value.ndim == 2:
            files.append(draw_surface(
                os.path.join(out, f'{key}.png'), pos, face,
                colors=colors, normal=normal,
                title=f"{title}\n{info['label']}, shown sRGB-encoded"))
        else:
            files.append(draw_surface(
                os.path.join(out, f'{key}.png'), pos, face, values=value,
                normal=normal, title=title, label=info['label'],
                cmap=info['cmap'], vmin=info['range'][0],
                vmax=info['range'][1]))
    return files


def _print_summary(out: str, report: dict):
    seen = report['observations_per_point']
    pipeline, seconds = report['pipeline'], report['seconds']
    capture = report['capture']
    left_out = capture.get('pixels_left_out') or {}
    dropped = ', '.join(f"{n} {why.replace('_', ' ')}"
                        for why, n in left_out.items() if n)
    lines = [
        f"{capture['format']} capture"
        + ('' if not capture.get('ldr') else
           f", 8-bit photographs at exposure {capture['exposure']:g}")
        + (f"; pixels left out: {dropped}" if dropped else ''),
        *capture.get('notes', []),
        f"{report['points']} points, {report['views']} views: "
        f"{seen['mean']:.1f} observations per point on average"
        + (f", {seen['unseen_points']} points unseen"
           if seen['unseen_points'] else ''),
        f"mean roughness uncertainty (std) "
        f"{report['mean_roughness_std']:.3f}, mean entropy "
        f"{report['mean_entropy']:.3f}"]
    if pipeline['fit'] is not None:
        fit = pipeline['fit']
        lines.append(f"spherical-harmonic fit: {fit['solver']}, "
                     f"{fit['steps']} steps in {seconds['fit']:.1f} s")
    if pipeline['refine'] is not None:
        refine = pipeline['refine']
        cap = refine.get('max_views')
        lines.append(f"refinement against the full integral: "
                     f"{refine['steps']} steps in {seconds['refine']:.1f} s "
                     f"({refine['visibility']} visibility, "
                     f"{refine['observations']:,} observations"
                     + ('' if cap is None else f", at most {cap} per point")
                     + ')')
    else:
        lines.append(f"not refined: {pipeline['not_refined_because']}")
    for name, (first, last) in report['loss'].items():
        lines.append(f"{name} loss {first:.4g} -> {last:.4g}")
    truth = report['ground_truth']
    if truth is not None:
        rho = truth['roughness_std_roughness_error_spearman']
        lines.append(
            f"against the ground truth: roughness MAE "
            f"{truth['roughness_mae']:.3f}, base colour RMSE "
            f"{truth['base_color_rmse']:.3f}"
            + (f", metallic MAE {truth['metallic_mae']:.3f}"
               if 'metallic_mae' in truth else '')
            + f", Spearman(roughness std, roughness error) "
            f"{'n/a' if rho is None else f'{rho:+.2f}'}")
    texture = report['texture']
    textures = '' if texture is None else (
        f", {texture['size']} x {texture['size']} textures on "
        f"{'the mesh' if texture['uv'] == 'mesh' else 'an atlas'}'s UVs "
        f"(*_texture.png, svbrdf.glb)")
    from tg_intrinsic.nn.svbrdf_result import MAP_INFO
    lines.append(f"wrote {out}: maps.npz, {', '.join(MAP_INFO)} (.ply and "
                 f".png){textures}, report.json ({seconds['total']:.1f} s)")
    print('\n'.join(lines))
