"""`tg-intrinsic demo --quick`: all four methods run and every promised
output exists (the quick numbers are a smoke test, not results)."""
import json

from tg_intrinsic.cli import main
from tg_intrinsic.cli.demo import PARTS, nearest_centroid

from tests.cli import assert_user_error, run_cli


def test_quick_demo_writes_summary_and_figures(tmp_path, capsys):
    out = tmp_path / 'demo'
    code = main(['demo', '--quick', '--quiet', '--out', str(out), '--root',
                 str(tmp_path / 'data')])
    printed = capsys.readouterr().out
    assert code == 0
    summary = json.loads((out / 'summary.json').read_text())
    assert summary['parts'] == list(PARTS)
    for part in PARTS:
        assert summary[part]['figures'], part
        for figure in summary[part]['figures']:
            assert (out / figure).stat().st_size > 10_000, figure
    for model in ('deltanet', 'hsn'):
        assert 0 <= summary[model]['test_accuracy'] <= 1
        assert (out / model / 'metrics.csv').exists()
    assert 'shape_dna_nearest_centroid' in summary['hsn']['baselines']
    gravo = summary['gravo']['problems']
    for problem in ('smoothing', 'poisson'):
        assert gravo[problem]['gravo']['converged']
        # Gravo MG, scipy and pyamg solve the same system
        assert gravo[problem]['gravo']['max_difference_to_direct'] < 1e-5
        assert gravo[problem]['pyamg_sa_cg']['max_difference_to_direct'] \
            < 1e-5
    assert gravo['smoothing']['noise_rms_after'] < \
        0.5 * gravo['smoothing']['noise_rms_before']
    assert gravo['poisson']['gravo']['max_error_to_known_solution'] < 1e-5
    # --quick is a smoke test, but one that shows learning: each network
    # beats the trivial baselines on the same test shapes (measured:
    # DeltaNet 60% against 32% for the bounding boxes, HSN 75% against 19%
    # and chance 8%)
    deltanet, hsn = summary['deltanet'], summary['hsn']
    assert deltanet['test_accuracy'] > \
        deltanet['baselines']['bounding_box_nearest_centroid'] + 0.1
    assert hsn['test_accuracy'] > 0.1 + max(
        hsn['baselines']['chance'],
        hsn['baselines']['bounding_box_nearest_centroid'])
    # its SVBRDF part is the command's default recovery, far past a
    # constant guess (measured: roughness MAE 0.013 against 0.117)
    svbrdf = summary['svbrdf']
    assert svbrdf['roughness_mae'] < 0.5 * svbrdf['constant_0.5_roughness_mae']
    assert 'FrequencySVBRDF.recover' in svbrdf['model']
    assert -1 <= svbrdf['spearman_entropy_vs_roughness_error'] <= 1
    text = (out / 'summary.md').read_text()
    assert 'a smoke test that every method runs and learns' in text
    for heading in ('DeltaNet', 'Harmonic Surface Network', 'Gravo MG',
                    'SVBRDF'):
        assert heading in text
    assert str(out.resolve()) in printed  # says where the results are


def test_demo_rejects_unknown_parts(tmp_path, capsys):
    code, _, err = run_cli(capsys, 'demo', '--only', 'everything')
    assert_user_error(code, err, 'demo', "invalid choice: 'everything'")


def test_nearest_centroid_baseline():
    import numpy as np
    train = np.array([[0.0, 0.0], [0.1, 0.0], [5.0, 5.0], [5.1, 5.0]])
    labels = np.array([0, 0, 1, 1])
    test = np.array([[0.2, 0.1], [4.9, 5.2]])
    assert nearest_centroid(train, labels, test, np.array([0, 1])) == 1.0
    assert nearest_centroid(train, labels, test, np.array([1, 0])) == 0.0


def test_demo_keeps_a_folder_of_other_files(tmp_path, capsys):
    (tmp_path / 'thesis.tex').write_text('mine')
    code, _, err = run_cli(capsys, 'demo', '--quick', '--out', tmp_path)
    assert_user_error(code, err, 'demo', 'thesis.tex', '--overwrite')
    assert [p.name for p in tmp_path.iterdir()] == ['thesis.tex']
