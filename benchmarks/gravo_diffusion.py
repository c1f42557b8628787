"""Learning diffusion times with GravoDiffusion: the layer solved by Gravo
MG against the same layer solved by scipy's sparse LU (the peer), on the
same run, same task, same optimiser.

Protocol: a bumpy torus of --major x --minor vertices (default 96 x 48 =
4608), scaled to unit area; a random signal (Gaussian noise, --channels
channels); the target is its implicit diffusion (M + t_c S) u_c = M x_c
for times log-spaced between --t-min and --t-max (solved by the LU),
unknown to the layer. Each arm starts from DiffusionNet's initial time 0
and takes --steps full-batch Rprop steps (initial step --lr, steps between
1e-8 and 1e-2) on the mean squared error. (Rprop, not Adam: the gradient
at t = 0 is about a hundred times the one near the answer, and Adam's
moment estimates stay dominated by it for dozens of steps: in trials on
this task, 40 Adam steps with learning rates 3e-4 to 1e-3 left one time
or more 90-1900% off, 40 Rprop steps all within 0.1%.)
Gravo MG solves to a relative residual of --tol, on a
hierarchy with --lower-bound points on its coarsest level. Timed: every
optimisation step (forward, backward, Rprop), the median over the steps
after the first, and the one-off set-up (operators; hierarchy for Gravo);
two CPU threads. Accuracy: learned vs true times per channel, and the
final loss relative to the loss of returning the input.

Usage: python benchmarks/gravo_diffusion.py [--steps 40] [--quick]
Writes benchmarks/results/gravo_diffusion.json and .png.
"""
import argparse
import os
import time

import matplotlib

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import torch  # noqa: E402
from torch_geometric.data import Data  # noqa: E402

from tg_intrinsic.geometry import normalize_area  # noqa: E402
from tg_intrinsic.nn import GravoDiffusion  # noqa: E402
from tg_intrinsic.solvers import diffuse  # noqa: E402
from tg_intrinsic.utils import atomic_write_json, machine_info  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))


def bumpy_torus(major: int, minor: int, seed: int = 0) -> Data:
    """A closed torus mesh of ``major x minor`` vertices with random
    bumps on its tube, scaled to unit area."""
    rng = np.random.default_rng(seed)
    u, v = np.meshgrid(2 * np.pi * np.arange(major) / major,
                       2 * np.pi * np.arange(minor) / minor, indexing='ij')
    r = 0.35 * (1 + 0.15 * np.sin(3 * u + rng.uniform(0, 6))
                * np.cos(2 * v + rng.uniform(0, 6)))
    pos = np.stack([(1 + r * np.cos(v)) * np.cos(u),
                    (1 + r * np.cos(v)) * np.sin(u), r * np.sin(v)], -1)
    index = np.arange(major * minor).reshape(major, minor)
    right, up = np.roll(index, -1, 0), np.roll(index, -1, 1)
    corner = np.roll(right, -1, 1)
    face = np.concatenate([np.stack([index, right, corner], 0).reshape(3, -1),
                           np.stack([index, corner, up], 0).reshape(3, -1)],
                          1)
    pos = torch.from_numpy(pos.reshape(-1, 3))
    face = torch.from_numpy(face)
    return Data(pos=normalize_area(pos, face), face=face)


class Arm:
    """One layer learning the times, with its optimiser and records."""

    def __init__(self, solver, data, channels, args):
        self.solver, self.data = solver, data
        self.layer = GravoDiffusion(channels, solver=solver, tol=args.tol,
                                    lower_bound=args.lower_bound)
        start = time.perf_counter()
        self.operators = self.layer.operators(data)
        self.setup = time.perf_counter() - start
        self.optimizer = torch.optim.Rprop(self.layer.parameters(),
                                           lr=args.lr,
                                           step_sizes=(1e-8, 1e-2))
        self.seconds, self.losses, self.times = [], [], []

    def step(self, x, target, baseline):
        start = time.perf_counter()
        self.optimizer.zero_grad()
        loss = (self.layer(x, self.data) - target).square().mean()
        loss.backward()
        self.optimizer.step()
        self.seconds.append(time.perf_counter() - start)
        self.losses.append(float(loss.detach()) / baseline)
        self.times.append(self.layer.time.detach().tolist())

    def summary(self, x, target, baseline, true_times):
        with torch.no_grad():
            final = float((self.layer(x, self.data) - target).square()
                          .mean()) / baseline
        learned = self.layer.time.detach().tolist()
        gravo = self.operators[2]
        return {
            'solver': self.solver, 'setup_s': self.setup,
            'levels': None if gravo is None else
            [gravo.num_points] + [P.shape[1] for P in gravo.prolongations],
            'step_s': float(np.median(self.seconds[1:])),
            'first_step_s': self.seconds[0], 'seconds': self.seconds,
            'relative_loss': self.losses, 'final_relative_loss': final,
            'times': self.times, 'learned_times': learned,
            'max_time_error': float(np.max(
                np.abs(np.array(learned) - true_times) / true_times))}


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument('--major', type=int, default=96)
    parser.add_argument('--minor', type=int, default=48)
    parser.add_argument('--channels', type=int, default=4)
    parser.add_argument('--t-min', type=float, default=2e-4)
    parser.add_argument('--t-max', type=float, default=5e-3)
    parser.add_argument('--steps', type=int, default=40)
    parser.add_argument('--lr', type=float, default=1e-4)
    parser.add_argument('--tol', type=float, default=1e-8)
    parser.add_argument('--lower-bound', type=int, default=100)
    parser.add_argument('--threads', type=int, default=2)
    parser.add_argument('--quick', action='store_true',
                        help='a 48 x 24 torus, 8 steps')
    parser.add_argument('--out', default=os.path.join(HERE, 'results'))
    args = parser.parse_args()
    if args.quick:
        args.major, args.minor, args.steps = 48, 24, 8
    torch.set_num_threads(args.threads)
    start = time.time()
    data = bumpy_torus(args.major, args.minor)
    g = torch.Generator().manual_seed(0)
    x = torch.randn(data.num_nodes, args.channels, generator=g,
                    dtype=torch.float64)
    true_times = np.geomspace(args.t_min, args.t_max, args.channels)
    S, m, _ = GravoDiffusion(1, solver='direct').operators(data)
    target = diffuse(S, m, x, torch.from_numpy(true_times), 'direct')
    baseline = float((x - target).square().mean())
    arms = [Arm(solver, data, args.channels, args)
            for solver in ('gravo', 'direct')]
    # in lockstep, the order alternating, so that a change in the load of
    # the machine meets both arms alike
    for step in range(args.steps):
        for arm in arms[::1 if step % 2 == 0 else -1]:
            arm.step(x, target, baseline)
    runs = {arm.solver: arm.summary(x, target, baseline, true_times)
            for arm in arms}
    for r in runs.values():
        print(f"{r['solver']:6s}: {1e3 * r['step_s']:.1f} ms per step "
              f"(set-up {r['setup_s']:.2f} s, levels {r['levels']}), "
              f"final relative loss {r['final_relative_loss']:.2e}, "
              f"largest time error {100 * r['max_time_error']:.2f}%",
              flush=True)
    gravo, direct = runs['gravo'], runs['direct']
    results = {
        'machine': machine_info(), 'quick': args.quick,
        'vertices': data.num_nodes, 'faces': data.face.size(1),
        'channels': args.channels, 'steps': args.steps, 'lr': args.lr,
        'tol': args.tol, 'lower_bound': args.lower_bound,
        'true_times': true_times.tolist(),
        'protocol': (f'bumpy torus of {data.num_nodes} vertices (unit '
                     f'area), {args.channels} channels of Gaussian noise, '
                     f'target: implicit diffusion for times '
                     f'{args.t_min:g}-{args.t_max:g}; times from 0, '
                     f'{args.steps} Rprop steps (initial step '
                     f'{args.lr:g}), MSE'),
        'step_ratio': direct['step_s'] / gravo['step_s'],
        'learned_time_difference': float(np.abs(
            np.array(gravo['learned_times']) -
            np.array(direct['learned_times'])).max() / true_times.max()),
        'runs': [gravo, direct],
        'total_seconds': time.time() - start}
    print(f"direct / Gravo MG time per step: {results['step_ratio']:.2f}x; "
          f"learned times differ by "
          f"{results['learned_time_difference']:.1e} of the largest",
          flush=True)
    atomic_write_json(os.path.join(args.out, 'gravo_diffusion.json'),
                      results)
    plot(results, args.out)


def plot(results, out):
    fig, ax = plt.subplots(1, 3, figsize=(14, 4))
    labels = {'gravo': 'Gravo MG', 'direct': 'sparse LU (splu)'}
    styles = {'gravo': '-', 'direct': '--'}
    for r in results['runs']:
        ax[0].semilogy(np.arange(1, len(r['relative_loss']) + 1),
                       r['relative_loss'], styles[r['solver']],
                       label=labels[r['solver']])
        times = np.array(r['times'])
        for c in range(times.shape[1]):
            ax[1].plot(np.arange(1, len(times) + 1), times[:, c],
                       styles[r['solver']], color=f'C{c}')
    for c, t in enumerate(results['true_times']):
        ax[1].axhline(t, color=f'C{c}', lw=0.8, ls=':')
    ax[0].set_xlabel('step')
    ax[0].set_ylabel('loss / loss of the input')
    ax[0].legend()
    ax[1].set_yscale('log')  # after the first step: every time > 0
    ax[1].set_xlabel('step')
    ax[1].set_ylabel('learned time (dotted: true)')
    ax[1].set_title('solid: Gravo MG, dashed: sparse LU', fontsize=9)
    names = [labels[r['solver']] for r in results['runs']]
    ax[2].bar(names, [1e3 * r['step_s'] for r in results['runs']],
              color=['C0', 'C7'])
    ax[2].set_ylabel('ms per optimisation step (median)')
    ax[2].set_title(f"{results['vertices']} vertices, "
                    f"{results['channels']} channels: "
                    f"{results['step_ratio']:.1f}x", fontsize=9)
    fig.tight_layout()
    fig.savefig(os.path.join(out, 'gravo_diffusion.png'), dpi=110)
    plt.close(fig)


if __name__ == '__main__':
    main()
