"""Benchmark: ``tg-intrinsic svbrdf`` as the capture grows (issue 42's
capture size: 100 photographs of 1600 x 1200 of a 250k-vertex mesh in at
most 10 minutes and 8 GiB on 2 cores, with --texture 2048).

Two series, each a synthetic capture of metals under a sun and sky written
as a COLMAP model of 8-bit sRGB PNG photographs, recovered with the
defaults and ``--texture 2048`` in a fresh process (report.json gives each
stage's seconds and the peak memory; the maps are scored against the
ground truth):

- ``small``: ``svbrdf --write-example`` (an icosphere) at every number of
  views and subdivision, photographs of ``--image-size`` squared;
- ``full`` (``--full``): the goal's size, a UV sphere of ``--vertices``
  (50k, 250k) seen by ``--full-views`` (25, 50, 100) photographs of
  1600 x 1200. The photographs are rendered and written one view at a time
  (a hundred of them do not fit in memory), once per mesh for the most
  views; a capture of fewer views is every second or fourth camera of
  that Fibonacci sphere (its own COLMAP model beside the same photographs,
  so its summary notes the photographs it does not list).

Writes ``benchmarks/results/svbrdf_capture_size.json`` (the series run are
replaced, the others kept) and ``svbrdf_capture_size.png``.

    python benchmarks/svbrdf_capture_size.py [--views 25 50 100]
        [--subdivisions 5 6] [--image-size 300]
    python benchmarks/svbrdf_capture_size.py --full [--vertices 50000
        250000] [--full-views 25 50 100]
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

import matplotlib

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402

sys.path.insert(0, os.path.join(os.path.dirname(__file__), '..'))
from tg_intrinsic.utils import (atomic_write, atomic_write_json,  # noqa: E402
                                machine_info)

RESULTS = os.path.join(os.path.dirname(os.path.abspath(__file__)), 'results')
COMMAND = [sys.executable, '-m', 'tg_intrinsic']
# the goals
GOAL_SECONDS, GOAL_GIB = 600, 8


def write_small(work: str, views: int, subdivisions: int, size):
    """``svbrdf --write-example`` as a COLMAP model of 8-bit photographs:
    (capture folder, exposure, seconds)."""
    capture = os.path.join(work, f'v{views}_s{subdivisions}')
    start = time.perf_counter()
    written = subprocess.run(
        COMMAND + ['svbrdf', '--write-example', capture, '--format',
                   'colmap', '--ldr', '--example-views', str(views),
                   '--example-image-size', str(size[0]),
                   '--example-subdivisions', str(subdivisions)],
        capture_output=True, text=True, check=True)
    # the example prints the command that recovers it, with --exposure
    line = written.stdout.strip().splitlines()[-1].split('next: ')[1]
    exposure = float(line.split('--exposure ')[1].split()[0])
    return capture, exposure, time.perf_counter() - start


def full_scene(vertices: int, views: int, size):
    """The goal-sized scene: a UV sphere of about ``vertices`` vertices
    (metals under a sun and sky), its seam welded, ``views`` cameras."""
    import math

    import numpy as np
    import torch

    from tg_intrinsic.datasets import svbrdf_scene
    rows = int(round(math.sqrt(vertices / 2)))
    # the truth's own observations are not needed: the fewest samples
    data = svbrdf_scene('uv_sphere', num_views=views,
                        image_size=tuple(size), materials='metals',
                        resolution=rows, render_images=False,
                        specular_samples=1, light_samples=1,
                        dtype=torch.float64)
    # the sphere's seam holds each vertex twice (for its UVs); the reader
    # welds them, so the truth must be of the welded points
    _, first, index = np.unique(data.pos.numpy().round(12), axis=0,
                                return_index=True, return_inverse=True)
    keep = np.sort(first)
    renumber = np.empty(len(first), dtype=np.int64)
    renumber[np.argsort(first)] = np.arange(len(first))
    for key in ('pos', 'normal', 'base_color', 'metallic', 'roughness'):
        data[key] = data[key][torch.from_numpy(keep)]
    data.face = torch.from_numpy(renumber[index.ravel()])[data.face]
    del data.uv
    return data


def write_full(work: str, vertices: int, views: int, size):
    """A capture of the goal's size, rendered and written one photograph
    at a time: a UV sphere of about ``vertices`` vertices (metals under a
    sun and sky), ``views`` cameras, 8-bit sRGB PNGs at the exposure that
    puts the 99.5th radiance percentile of the first views at 0.9.
    Returns (folder, exposure, seconds, the COLMAP images and cameras)."""
    import numpy as np
    import torch
    from PIL import Image

    from tg_intrinsic.datasets.capture import render_images
    from tg_intrinsic.io.capture_writer import ldr_exposure
    from tg_intrinsic.io.colmap import write_colmap_model
    from tg_intrinsic.io.gltf import srgb_encode
    from tg_intrinsic.io.hdr import write_hdr
    from tg_intrinsic.io.mesh import write_ply
    start = time.perf_counter()
    folder = os.path.join(work, f'full_{vertices}')
    # a capture written before into --work, whole, is taken as it is
    written = os.path.join(folder, 'written.json')
    if os.path.exists(written):
        before = json.load(open(written))
        if before['views'] == views and before['size'] == list(size):
            return (folder, before['exposure'], before['seconds'],
                    [dict(image, R=np.array(image['R']),
                          t=np.array(image['t']))
                     for image in before['images']],
                    {int(k): dict(v, params=np.array(v['params']))
                     for k, v in before['cameras'].items()})
    os.makedirs(os.path.join(folder, 'images'), exist_ok=True)
    data = full_scene(vertices, views, size)
    normal = data.normal.numpy()
    write_ply(os.path.join(folder, 'geometry.ply'), data.pos.numpy(),
              data.face.t().numpy(), {'nx': normal[:, 0],
                                      'ny': normal[:, 1],
                                      'nz': normal[:, 2]})
    write_hdr(os.path.join(folder, 'envmap.hdr'), data.envmap.numpy())
    np.savez(os.path.join(folder, 'ground_truth.npz'),
             **{name: data[name].numpy() for name in
                ('base_color', 'metallic', 'roughness', 'pos')})

    def render(view: int):
        return render_images(
            data.pos, data.face, data.normal, data.base_color,
            data.metallic, data.roughness, data.intrinsics[view:view + 1],
            data.extrinsics[view:view + 1], size[0], size[1],
            data.envmap, seed=view)[0]
    first = [render(v) for v in range(4)]
    exposure = ldr_exposure(torch.stack(first))
    for view in range(views):
        image = first[view] if view < 4 else render(view)
        codes = np.round(srgb_encode(np.clip(
            image.double().numpy() * exposure, 0, 1)) * 255)
        Image.fromarray(codes.astype(np.uint8), 'RGB').save(
            os.path.join(folder, 'images', f'{view:03d}.png'))
        print(f'  photograph {view + 1}/{views} '
              f'({time.perf_counter() - start:.0f} s)', flush=True)
    K, E = data.intrinsics.numpy(), data.extrinsics.numpy()
    cameras = {1: {'model': 'PINHOLE', 'height': size[0], 'width': size[1],
                   'params': np.array([K[0, 0, 0], K[0, 1, 1], K[0, 0, 2],
                                       K[0, 1, 2]])}}
    images = [{'image_id': v + 1, 'camera_id': 1, 'name': f'{v:03d}.png',
               'R': E[v, :, :3], 't': E[v, :, 3]} for v in range(views)]
    write_colmap_model(os.path.join(folder, 'sparse', '0'), cameras, images)
    seconds = time.perf_counter() - start
    atomic_write_json(written, {
        'views': views, 'size': list(size), 'exposure': float(exposure),
        'seconds': seconds,
        'images': [dict(image, R=image['R'].tolist(), t=image['t'].tolist())
                   for image in images],
        'cameras': {k: dict(v, params=v['params'].tolist())
                    for k, v in cameras.items()}})
    return folder, float(exposure), seconds, images, cameras


def fewer_views(folder: str, images, cameras, every: int) -> str:
    """The capture of every ``every``-th camera: its own COLMAP model
    beside the same photographs (a link to the folder)."""
    from tg_intrinsic.io.colmap import write_colmap_model
    subset = f'{folder}_every{every}'
    os.makedirs(subset, exist_ok=True)
    for name in ('images', 'geometry.ply', 'envmap.hdr',
                 'ground_truth.npz'):
        if not os.path.lexists(os.path.join(subset, name)):
            os.symlink(os.path.join(folder, name),
                       os.path.join(subset, name))
    write_colmap_model(os.path.join(subset, 'sparse', '0'), cameras,
                       images[::every])
    return subset


def recover(capture: str, exposure: float, out: str) -> dict:
    """``svbrdf CAPTURE --exposure S --texture 2048`` in a fresh process:
    its wall time, report and errors."""
    start = time.perf_counter()
    subprocess.run(COMMAND + ['svbrdf', capture, '--exposure',
                              f'{exposure:.9g}', '--texture', '2048',
                              '--out', out, '--quiet'], check=True)
    wall = time.perf_counter() - start
    report = json.loads(open(os.path.join(out, 'report.json')).read())
    return {'views': report['views'], 'points': report['points'],
            'image_size': report['image_size'], 'wall_s': round(wall, 2),
            'seconds': report['seconds'],
            'peak_memory_gib': report['peak_memory_gib'],
            'observations_per_point': report['observations_per_point'],
            'pixels_left_out': report['capture']['pixels_left_out'],
            'ground_truth': report['ground_truth']}


def plot(series, path):
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for name, runs in series.items():
        for points in sorted({r['points'] for r in runs}):
            rows = sorted((r for r in runs if r['points'] == points),
                          key=lambda r: r['views'])
            size = rows[0]['image_size']
            label = f"{points:,} points, {size[1]} x {size[0]}"
            views = [r['views'] for r in rows]
            style = 'o-' if name == 'full' else 's--'
            axes[0].plot(views, [r['wall_s'] for r in rows], style,
                         label=label)
            axes[1].plot(views, [r['peak_memory_gib'] for r in rows], style,
                         label=label)
    axes[0].axhline(GOAL_SECONDS, color='k', lw=0.8, ls=':')
    axes[1].axhline(GOAL_GIB, color='k', lw=0.8, ls=':')
    axes[0].set_ylabel('seconds (whole command, --texture 2048)')
    axes[1].set_ylabel('peak memory (GiB)')
    for ax in axes:
        ax.set_xlabel('views')
        ax.legend(fontsize=8)
        ax.grid(alpha=0.3)
    fig.suptitle("svbrdf on 2 CPU cores as the capture grows (COLMAP, "
                 "8-bit photographs; dotted: the goal)")
    fig.tight_layout()
    atomic_write(path, lambda f: fig.savefig(f, format='png', dpi=110),
                 'wb')


def main():
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--views', type=int, nargs='+', default=[25, 50])
    parser.add_argument('--subdivisions', type=int, nargs='+',
                        default=[5, 6], help='icosphere subdivisions: 5 '
                        'gives 10,242 points, 6 40,962, 7 163,842')
    parser.add_argument('--image-size', type=int, default=300,
                        help='side of the square photographs of the small '
                        'series')
    parser.add_argument('--full', action='store_true',
                        help="run the goal's series instead")
    parser.add_argument('--vertices', type=int, nargs='+',
                        default=[50000, 250000])
    parser.add_argument('--full-views', type=int, nargs='+',
                        default=[25, 50, 100], help='each must divide the '
                        'most')
    parser.add_argument('--full-size', type=int, nargs=2,
                        default=[1200, 1600], metavar=('HEIGHT', 'WIDTH'))
    parser.add_argument('--work', default=None,
                        help='folder for the captures (default: a '
                        'temporary one, deleted)')
    args = parser.parse_args()
    path = os.path.join(RESULTS, 'svbrdf_capture_size.json')
    old = json.load(open(path)) if os.path.exists(path) else {}
    series = dict(old.get('series', {}))
    if 'runs' in old:  # the first layout: the small series alone
        series.setdefault('small', old['runs'])
    with tempfile.TemporaryDirectory(prefix='capture-size-') as scratch:
        work = args.work or scratch
        runs = []
        if args.full:
            most = max(args.full_views)
            for vertices in args.vertices:
                folder, exposure, seconds, images, cameras = write_full(
                    work, vertices, most, args.full_size)
                print(f'wrote {folder} in {seconds:.0f} s', flush=True)
                for views in sorted(args.full_views):
                    capture = folder if views == most else fewer_views(
                        folder, images, cameras, most // views)
                    run = recover(capture, exposure, os.path.join(
                        work, f'out_{vertices}_{views}'))
                    run['write_capture_s'] = round(seconds, 2)
                    print(json.dumps({k: run[k] for k in (
                        'views', 'points', 'wall_s', 'peak_memory_gib')}),
                        flush=True)
                    runs.append(run)
        else:
            for subdivisions in args.subdivisions:
                for views in args.views:
                    capture, exposure, seconds = write_small(
                        work, views, subdivisions,
                        (args.image_size, args.image_size))
                    run = recover(capture, exposure, os.path.join(
                        work, f'out_v{views}_s{subdivisions}'))
                    run['write_capture_s'] = round(seconds, 2)
                    print(json.dumps({k: run[k] for k in (
                        'views', 'points', 'wall_s', 'peak_memory_gib')}),
                        flush=True)
                    runs.append(run)
    series['full' if args.full else 'small'] = runs
    os.makedirs(RESULTS, exist_ok=True)
    atomic_write_json(path, {
        'machine': machine_info(), 'goal': {
            'views': 100, 'image_size': [1200, 1600], 'points': 250000,
            'seconds': GOAL_SECONDS, 'peak_memory_gib': GOAL_GIB},
        'series': series})
    plot(series, os.path.join(RESULTS, 'svbrdf_capture_size.png'))


if __name__ == '__main__':
    main()
