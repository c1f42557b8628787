"""The demo as a benchmark: runs ``tg-intrinsic demo`` (the full mode that
``make demo`` runs) in a fresh folder and keeps its summary as
``benchmarks/results/demo.json`` with a plot of its headline numbers, so
the README reports the demo from a recorded run.

    python benchmarks/demo.py [--summary runs/demo/summary.json]

``--summary`` records an existing run instead of running the demo again.
"""
import argparse
import json
import os
import shutil
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(
    __file__))))

from tg_intrinsic.cli import main as cli  # noqa: E402
from tg_intrinsic.io.figures import save_figure  # noqa: E402
from tg_intrinsic.utils import atomic_write_json  # noqa: E402

RESULTS = os.path.join(os.path.dirname(os.path.abspath(__file__)),
                       'results')


def plot(summary: dict, path: str):
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.8))
    names, values = [], []
    for model in ('deltanet', 'hsn'):
        part = summary[model]
        names.append(f'{model}\n(trained)')
        values.append(part['test_accuracy'])
        for key, value in part['baselines'].items():
            if key != 'chance':
                names.append(f"{model}: {key.split('_nearest')[0]}\n"
                             f"nearest centroid")
                values.append(value)
    axes[0].barh(names, values, color=['C0', 'C1', 'C0', 'C1', 'C2'][
        :len(values)])
    axes[0].set_xlabel('test accuracy')
    axes[0].set_xlim(0, 1)
    axes[0].set_title('learning: networks vs baselines')
    gravo = summary['gravo']
    problems = gravo['problems']
    labels = list(problems)
    width = 0.27
    for k, (solver, key) in enumerate((
            ('Gravo MG: setup + solve', 'gravo'),
            ('scipy direct', 'scipy_direct'),
            ('pyamg SA + CG: setup + solve', 'pyamg_sa_cg'))):
        where = [i + (k - 1) * width for i in range(len(labels))]
        if key == 'gravo':
            heights = [problems[p][key]['setup_seconds'] +
                       problems[p][key]['solve_seconds'] for p in labels]
            axes[1].bar(where, [gravo['hierarchy_seconds']] * len(labels),
                        width, bottom=heights, color='C0', alpha=0.4,
                        hatch='//', label='Gravo MG: hierarchy, once per '
                        'surface')
        else:
            heights = [problems[p][key]['seconds'] for p in labels]
        axes[1].bar(where, heights, width, label=solver,
                    color=f'C{k}')
    axes[1].set_xticks(range(len(labels)), labels)
    axes[1].set_ylabel('seconds')
    axes[1].set_title(f"Gravo MG, {summary['gravo']['vertices']:,} vertices")
    axes[1].legend(fontsize=8)
    sv = summary['svbrdf']
    axes[2].bar(['roughness MAE', 'base colour RMSE'],
                [sv['roughness_mae'], sv['base_color_rmse']], 0.35,
                label='recovered')
    axes[2].bar([0.35, 1.35], [sv['constant_0.5_roughness_mae'],
                               sv['constant_0.5_base_color_rmse']], 0.35,
                label='constant 0.5')
    axes[2].set_ylabel('error (parameter units)')
    axes[2].set_title('SVBRDF recovery vs ground truth')
    axes[2].legend(fontsize=8)
    fig.suptitle(f"tg-intrinsic demo, {summary['seconds']:.0f} s on "
                 f"{summary['machine']['cpu_count']} CPU cores")
    fig.tight_layout()
    save_figure(fig, path)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--summary', default=None,
                        help="an existing run's summary.json to record")
    args = parser.parse_args(argv)
    if args.summary is None:
        folder = tempfile.mkdtemp(prefix='tg_demo_')
        try:
            if cli(['demo', '--out', os.path.join(folder, 'demo'), '--root',
                    os.path.join(folder, 'data')]) != 0:
                raise SystemExit('the demo failed')
            summary = json.load(open(os.path.join(folder, 'demo',
                                                  'summary.json')))
        finally:
            shutil.rmtree(folder, ignore_errors=True)
    else:
        summary = json.load(open(args.summary))
    if summary['quick'] or summary['parts'] != ['deltanet', 'hsn', 'gravo',
                                                'svbrdf']:
        raise SystemExit('record a full demo of all four parts')
    atomic_write_json(os.path.join(RESULTS, 'demo.json'), summary)
    plot(summary, os.path.join(RESULTS, 'demo.png'))
    print(f"wrote {os.path.join(RESULTS, 'demo.json')} and demo.png")


if __name__ == '__main__':
    main()
