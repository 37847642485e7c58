"""The down-camera comparison benches' quick variants (CI): every baseline row still flies its
step, and each comparison with ours points the way the full bench finds it
(:data:`autopilot.bench.down.QUICK`). One seed of a shortened default scenario each."""

import json

import pytest

from autopilot.bench import down
from autopilot.cli import main


# about 20 s (hover_image) and 30 s (land_pad: seed 001's 13 templates a frame) of CPU
@pytest.mark.parametrize("bench", ["hover_image", "land_pad"])
def test_quick_variant_flies_every_row_and_keeps_its_direction(bench, capsys):
    assert main(["bench", bench, "--quick", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["quick"]
    assert result["seeds"] == 1
    assert set(result["scenarios"]["default"]["runs"]) == set(down.BENCHES[bench].rows)
    assert down.quick_checks(result) == []
