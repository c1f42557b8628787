"""What a run writes: one run at a time into --out, the metrics CSV."""
import csv

import pytest

from tg_intrinsic.training.outputs import CSV_COLUMNS, write_metrics_csv
from tests.training import run


def test_the_metrics_csv_has_a_row_per_epoch(tmp_path):
    history = [{'epoch': 1, 'train_loss': 2.0, 'train_accuracy': 0.25},
               {'epoch': 2, 'train_loss': 1.5, 'train_accuracy': 0.5,
                'test_accuracy': 0.75}]
    write_metrics_csv(history, str(tmp_path / 'metrics.csv'))
    with open(tmp_path / 'metrics.csv') as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0]) == list(CSV_COLUMNS)
    assert [row['epoch'] for row in rows] == ['1', '2']
    assert rows[0]['test_accuracy'] == '' and \
        float(rows[1]['test_accuracy']) == 0.75


def test_a_second_run_into_the_same_out_stops_at_once(tmp_path):
    from tg_intrinsic.io.results import output_lock
    out = tmp_path / 'run'
    with output_lock(str(out)):   # another run holds it
        with pytest.raises(ValueError, match=r"--out '.*run' is being "
                           r"written by another run of tg-intrinsic"):
            run(tmp_path, '--epochs', '1')
    assert not out.exists()
    run(tmp_path, '--epochs', '1')   # free again
    assert (out / 'checkpoint.pt').exists()
