"""The ledger of model versions: record, read back, label, plot, CLI."""

import json

import numpy as np
import pytest

from fenicsx_drape.cli import main
from fenicsx_drape.diagnosis import CompareResult, ledger
from fenicsx_drape.diagnosis.kinds import Comparison
from fenicsx_drape.errors import DrapeInputError
from fenicsx_drape.measurements.bundle import Bundle
from fenicsx_drape.model import Model


def _result(effects, errors):
    comparisons = []
    for i, error in enumerate(errors):
        measured = np.linspace(0, 10, 50)
        residual = np.full(50, error)  # RMSE = error, noise 0.5
        comparisons.append(Comparison(f"bias-{i}", "bias_extension", "N", measured,
                                      measured - residual, 0.5, "force_sd_N", (), {}))
    return CompareResult("demo", Model(effects), tuple(comparisons))


def test_ledger_records_versions_in_order_with_changes(tmp_path):
    bundle = Bundle(name="demo", tests=(), path=tmp_path)
    versions = [(("decrimping",), [2.0, 4.0]),
                (("decrimping", "rate_dependence"), [0.8, 1.0]),
                (("decrimping", "rate_dependence"), [0.5, 0.6])]
    for k, (effects, errors) in enumerate(versions):
        ledger.record(tmp_path / f"v{k}", _result(effects, errors), bundle=bundle)
    # The same folder twice, and a second version in one folder, are read once each.
    ledger.record(tmp_path / "v2", _result(("decrimping",), [3.0, 3.0]), bundle=bundle)
    dirs = [tmp_path / "v0", tmp_path / "v1", tmp_path / "v2", tmp_path / "v0"]
    history = ledger.history(dirs, out_dir=tmp_path / "history")
    assert [v.label for v in history] == ["v1", "v2", "v3", "v4"]
    assert [v.change for v in history] == ["first version", "+rate_dependence",
                                           "same model (refit)", "-rate_dependence"]
    # normalised = sqrt(mean((RMSE / noise)²)) of the recorded comparison
    assert history[0].entry["normalised"] == pytest.approx(np.sqrt((16 + 64) / 2))
    assert history[2].entry["normalised"] == pytest.approx(np.sqrt((1 + 1.44) / 2))
    assert (tmp_path / "history" / "history.png").stat().st_size > 1000
    saved = json.loads((tmp_path / "history" / "history.json").read_text())
    assert [e["version"] for e in saved] == ["v1", "v2", "v3", "v4"]
    assert (tmp_path / "history" / "provenance.json").is_file()
    text = ledger.history_table(history)
    assert "+rate_dependence" in text and text.count("\n") == 5


def test_history_rejects_folders_without_a_ledger_and_bad_lines(tmp_path):
    with pytest.raises(DrapeInputError, match=r"no ledger\.jsonl"):
        ledger.read([tmp_path])
    (tmp_path / "ledger.jsonl").write_text('{"id": "x"}\n')
    with pytest.raises(DrapeInputError, match=r"ledger.jsonl:1: not a ledger entry"):
        ledger.read([tmp_path])


def test_history_command(tmp_path, capsys):
    bundle = Bundle(name="demo", tests=(), path=tmp_path)
    ledger.record(tmp_path / "a", _result(("decrimping",), [2.0]), bundle=bundle)
    ledger.record(tmp_path / "b", _result(("decrimping", "tow_buckling"), [1.0]),
                  bundle=bundle)
    out = tmp_path / "hist"
    assert main(["history", str(tmp_path / "a"), str(tmp_path / "b"), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "+tow_buckling" in printed and (out / "history.png").is_file()
    assert main(["history", str(tmp_path / "missing")]) == 2
