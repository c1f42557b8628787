"""benchmarks/report.py: the README's results table is what the benchmark
JSONs say, and follows them."""
import importlib.util
import json
import os
import re
import shutil
import subprocess
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCRIPT = os.path.join(ROOT, 'benchmarks', 'report.py')
RESULTS = os.path.join(ROOT, 'benchmarks', 'results')
README = os.path.join(ROOT, 'README.md')

spec = importlib.util.spec_from_file_location('report', SCRIPT)
report = importlib.util.module_from_spec(spec)
spec.loader.exec_module(report)


@pytest.fixture
def copies(tmp_path):
    """The results JSONs and the README, copied."""
    results = tmp_path / 'results'
    results.mkdir()
    for name in os.listdir(RESULTS):
        if name.endswith('.json'):
            shutil.copy(os.path.join(RESULTS, name), results / name)
    readme = tmp_path / 'README.md'
    shutil.copy(README, readme)
    return results, readme


def edit(path, change):
    with open(path) as f:
        data = json.load(f)
    change(data)
    with open(path, 'w') as f:
        json.dump(data, f)


def changed_lines(results, before):
    """The rows of the table built from ``results`` that ``before`` (an
    earlier table) lacks."""
    after = report.build_table(str(results))
    return [line for line in after.split('\n')
            if line not in before.split('\n')]


def test_readme_matches_the_results():
    run = subprocess.run([sys.executable, SCRIPT, '--check'],
                         capture_output=True, text=True)
    assert run.returncode == 0, (
        'README.md differs from benchmarks/results; run python '
        'benchmarks/report.py\n' + run.stdout[-3000:] + run.stderr)


def test_every_result_has_a_row():
    names = sorted(os.path.splitext(n)[0] for n in os.listdir(RESULTS)
                   if n.endswith('.json'))
    assert sorted(set(report.ROWS) - (set(report.UNVERIFIED) - set(names))
                  ) == names
    table = report.build_table(RESULTS)
    for name in names:
        assert f'`{name}.py`' in table


def test_a_changed_number_changes_the_table(copies, capsys):
    results, readme = copies
    before = report.build_table(str(results))

    def faster_knn(data):
        row = data['results'][0]
        assert (row['op'], row['n']) == ('knn', 10000)
        row['speedup'] = 999.0

    edit(results / 'neighbors.json', faster_knn)
    after = report.build_table(str(results))
    assert before != after
    assert '-999x' not in before and re.search(r'knn [\d.]+-999x', after)
    changed = [line for line in after.split('\n')
               if line not in before.split('\n')]
    assert len(changed) == 1 and changed[0].startswith('| knn / radius')

    # --check sees it and prints a diff; a rewrite fixes it, and leaves
    # everything outside the markers as it was
    args = ['--results', str(results), '--readme', str(readme)]
    assert report.main(args + ['--check']) == 1
    assert '+| knn / radius / fps' in capsys.readouterr().out
    original = readme.read_text()
    assert report.main(args) == 0
    assert report.main(args + ['--check']) == 0
    text = readme.read_text()
    assert re.search(r'knn [\d.]+-999x', text)
    assert text.split(report.START)[0] == original.split(report.START)[0]
    assert text.split(report.END)[1] == original.split(report.END)[1]


def test_a_number_deep_inside_a_benchmark_changes_its_row(copies):
    results, _ = copies
    before = report.build_table(str(results))

    def nan_no_more(data):
        for goal in data['goals']:
            goal.pop('original_failed', None)

    edit(results / 'gravo_mg.json', nan_no_more)
    after = report.build_table(str(results))
    assert 'the original fails' in before
    assert 'the original fails' not in after


def test_a_new_benchmark_without_a_row_is_an_error(copies, capsys):
    results, readme = copies
    (results / 'shiny_new.json').write_text('{"speedup": 3}')
    with pytest.raises(report.ReportError, match='shiny_new.json'):
        report.build_table(str(results))
    assert report.main(['--check', '--results', str(results),
                        '--readme', str(readme)]) == 2
    assert 'shiny_new.json' in capsys.readouterr().err


def test_a_row_without_results_is_an_error(copies):
    results, _ = copies
    os.remove(results / 'svbrdf_speed.json')
    with pytest.raises(report.ReportError, match='svbrdf_speed.json'):
        report.build_table(str(results))


def test_a_json_missing_a_key_names_the_benchmark(copies):
    results, _ = copies
    edit(results / 'hsn_accuracy.json', lambda data: data.pop('epochs'))
    with pytest.raises(report.ReportError, match='hsn_accuracy.json'):
        report.build_table(str(results))


def test_markers_are_required(tmp_path):
    readme = tmp_path / 'README.md'
    readme.write_text('# no table here\n')
    with pytest.raises(report.ReportError, match='results:start'):
        report.with_table(readme.read_text(), '| a |')
    assert report.main(['--check', '--readme', str(readme)]) == 2


def test_formatting_helpers():
    assert report.times(9.96) == '10x' and report.times(6.26) == '6.3x'
    assert report.span_times([13.97, 115.5]) == '14-116x'
    assert report.sci(0.004721) == '5e-3'
    assert report.sig(4648.456) == '4650' and report.seconds(8.57) == '8.6'
    assert report.thousands(2500) == '2.5k' and \
        report.thousands(49999) == '50k' and \
        report.thousands(2028099) == '2.0M'
    assert report.span_pct([0.8613, 1.0]) == '86-100%'
    assert report.test_set_size([0.95, 0.925, 1 / 12, 109 / 120]) == 120


def test_the_part_segmentation_row_follows_its_numbers(copies):
    results, _ = copies
    before = report.build_table(str(results))

    def better(data):
        data['runs'][0]['final_instance_miou'] = 0.987

    edit(results / 'part_segmentation.json', better)
    after = report.build_table(str(results))
    assert '98.7%' not in before and '98.7%' in after


def test_the_correspondence_row_follows_its_curves(copies):
    results, _ = copies
    before = report.build_table(str(results))

    def better_hsn(data):
        run = data['runs'][0]
        assert run['model'].startswith('HSN')
        run['within_0.05'] = 0.987

    edit(results / 'hsn_correspondence.json', better_hsn)
    changed = changed_lines(results, before)
    assert len(changed) == 1 and '**98.7% within 0.05**' in changed[0]


def test_sphere_digits_and_perona_malik_rows_follow_their_numbers(copies):
    results, _ = copies
    before = report.build_table(str(results))

    def worse_turned(data):
        run = data['runs'][0]
        assert (run['training'], run['max_order']) == ('upright', 1)
        run['test_turned'] = 0.123

    def better_delta(data):
        assert data['runs'][0]['model'].startswith('DeltaConv')
        data['runs'][0]['test_rel_l2'] = 0.0456

    edit(results / 'sphere_digits.json', worse_turned)
    edit(results / 'perona_malik.json', better_delta)
    changed = changed_lines(results, before)
    assert len(changed) == 2
    assert 'trained upright: **turned test 12.3% vs' in changed[0]
    assert '**DeltaConv 0.05** vs' in changed[1]


def test_the_ddp_training_row_follows_its_numbers(copies):
    results, _ = copies
    before = report.build_table(str(results))

    def slower_two_processes(data):
        rows = data['models']['deltanet']['configurations']
        assert rows[2]['label'] == '2 processes x 1 thread'
        rows[2]['epoch_seconds'] = rows[0]['epoch_seconds'] / 1.5

    edit(results / 'ddp_training.json', slower_two_processes)
    changed = changed_lines(results, before)
    assert len(changed) == 1 and 'deltanet' in changed[0]
    assert 'speed-up 1.50x over 1 process x 2 threads' in changed[0]


def test_the_out_of_core_row_follows_its_numbers(copies):
    results, _ = copies
    before = report.build_table(str(results))

    def grown(data):
        largest = max(r['size'] for r in data['rows'])
        for r in data['rows']:
            if r['arm'] == 'on_disk' and r['size'] == largest:
                r['peak_mb'] = 98765.4
        data['preparation']['identical'] = False

    edit(results / 'out_of_core.json', grown)
    changed = changed_lines(results, before)
    assert len(changed) == 1
    assert ', 98765 MB (' in changed[0]
    assert 'identical databases: NO' in changed[0]


def test_the_gravo_scale_row_follows_its_numbers(copies):
    results, _ = copies
    before = report.build_table(str(results))

    def slower_and_larger(data):
        # the original's time counts only where its answer is not NaN
        compared = [r for r in data['rows']
                    if 'original_failed' not in r['poisson']][-1]
        compared['poisson']['solve_ratio'] = 1.37
        compared['poisson']['ours']['added_mb_per_million'] = 4321

    edit(results / 'gravo_scale.json', slower_and_larger)
    changed = changed_lines(results, before)
    assert len(changed) == 1 and 'gravo_scale.py' in changed[0]
    assert '**1.37x**' in changed[0] and '4321 vs' in changed[0]


def gpu_results(**changes):
    """A gpu.json as benchmarks/gpu.py writes it on CUDA."""
    data = {
        'device': 'NVIDIA H200', 'quick': False, 'seconds': 412.0,
        'goals': report_goals()[0],
        'device_tests': {'exit_code': 0, 'summary': '31 passed in 80s'},
        'neighbours': {'knn_100k_s': 0.15, 'knn_32x1024_s': 0.012,
                       'mls_100k_s': 0.4, 'mls_32x1024_s': 0.02,
                       'knn_same_graph_as_cpu': True},
        'networks': {'deltanet_step_s': 0.040, 'dgcnn_step_s': 0.070,
                     'deltanet_vs_dgcnn': 1.75},
        'uncertainty': {'spectral_uncertainty_100k_s': 0.0008},
        'svbrdf': {'svbrdf_device': {'wall_s': 6.0},
                   'svbrdf_cpu': {'wall_s': 18.0}, 'svbrdf_speedup': 3.0},
        'epochs': {'deltanet_epoch_s': 0.7, 'hsn_epoch_s': 5.5}}
    data.update(changes)
    # what gpu.py judges at its end
    goals, at_least = report_goals()
    figures = {k: v for name, part in data.items() if name != 'goals'
               and isinstance(part, dict) for k, v in part.items()}
    data['at_least'] = list(at_least)
    data['met'] = {key: (figures[key] >= bound if key in at_least
                         else figures[key] <= bound)
                   for key, bound in goals.items() if key in figures}
    return data


def report_goals():
    spec = importlib.util.spec_from_file_location(
        'gpu_benchmark', os.path.join(ROOT, 'benchmarks', 'gpu.py'))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.GOALS, module.AT_LEAST


def test_the_gpu_row_says_not_verified_without_its_json(copies):
    results, _ = copies
    if (results / 'gpu.json').exists():
        os.remove(results / 'gpu.json')
    table = report.build_table(str(results))
    row = [line for line in table.splitlines() if '`gpu.py`' in line]
    assert len(row) == 1 and 'not verified' in row[0]


def test_the_gpu_row_follows_its_numbers(copies):
    results, _ = copies
    (results / 'gpu.json').write_text(json.dumps(gpu_results()))
    row = [line for line in report.build_table(str(results)).splitlines()
           if '`gpu.py`' in line][0]
    assert 'not verified' not in row and 'NVIDIA H200' in row
    assert '31 passed' in row
    assert '150 ms (goal <= 200 ms, met)' in row          # knn 100k
    assert '12 ms (goal <= 10 ms, **not met**)' in row    # knn 32 x 1024
    assert '1.75x (goal >= 1.50x, met)' in row            # vs DGCNN
    assert '0.8 ms (goal <= 1 ms, met)' in row
    assert 'HSN 5.5 s (goal <= 5 s, **not met**)' in row
    failed = gpu_results(epochs={'error': 'RuntimeError: out of memory'})
    (results / 'gpu.json').write_text(json.dumps(failed))
    row = [line for line in report.build_table(str(results)).splitlines()
           if '`gpu.py`' in line][0]
    assert 'epochs failed (RuntimeError: out of memory)' in row


def test_a_gpu_check_on_the_cpu_is_not_taken_for_results(copies):
    results, _ = copies
    (results / 'gpu.json').write_text(json.dumps(gpu_results(
        device='cpu', quick=True)))
    with pytest.raises(report.ReportError, match='not the results'):
        report.build_table(str(results))


def test_the_svbrdf_rows_report_the_default_pipeline(copies):
    results, _ = copies

    def row(name):
        return [line for line in report.build_table(str(results)).split(
            '\n') if f'`{name}.py`' in line][0]
    assert "**The command's default reaches issue 32's goals" in row(
        'svbrdf_accuracy')

    def all_met(data):
        for goal in data['default_goals'].values():
            goal['missed_by'] = []
    edit(results / 'svbrdf_accuracy.json', all_met)
    runs = json.loads((results / 'svbrdf_accuracy.json').read_text())[
        'default_goals']['roughness_mae']['runs']
    assert f"goals (roughness MAE <= 0.04, base RMSE <= 0.06) in {runs} of " \
        f"{runs} runs**, in" in row('svbrdf_accuracy')
    # the Mitsuba comparison names the default's stages and its verdict
    mitsuba = [line for line in report.build_table(str(results)).split('\n')
               if "the command's default (full-integral" in line][0]
    assert 'tables over roughness' in mitsuba and 'goal: at most a third' \
        in mitsuba


def test_the_gravo_diffusion_row_follows_its_numbers(copies):
    results, _ = copies
    before = report.build_table(str(results))

    def slower_gravo(data):
        gravo, direct = data['runs']
        assert (gravo['solver'], direct['solver']) == ('gravo', 'direct')
        data['step_ratio'] = 0.5
        gravo['max_time_error'] = 0.0321

    edit(results / 'gravo_diffusion.json', slower_gravo)
    changed = changed_lines(results, before)
    assert len(changed) == 1
    assert '**Gravo MG 2.0x slower per step**' in changed[0]
    assert 'learned times within 3.21% (Gravo MG)' in changed[0]


def test_the_compile_precision_row_follows_its_numbers(copies):
    results, _ = copies
    before = report.build_table(str(results))

    def slower_compile(data):
        data['speed']['deltanet_classification']['compiled_speedup'] = 0.5
        data['accuracy']['hsn']['points_apart'] = 12.34

    edit(results / 'compile_precision.json', slower_compile)
    changed = changed_lines(results, before)
    assert len(changed) == 1
    assert 'deltanet classification: compiled 0.5x' in changed[0]
    assert '**12.3 points apart**' in changed[0]
