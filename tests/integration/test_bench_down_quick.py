"""The down-camera comparison benches' quick variants (CI): every baseline row still flies its
step, and each comparison with ours points the way the full bench finds it
(:data:`autopilot.bench.down.QUICK`). One seed of a shortened default scenario each."""

import json

import pytest

from autopilot.bench import down
from autopilot.cli import main


# about 20 s (hover_image) and 30 s (land_pad: seed 001's 13 templates a frame) of CPU
# (hover_image's flights go to a worker process each, as by default; land_pad's fly here, one
# after the other: the CI machine's cores are shared)
@pytest.mark.parametrize(("bench", "workers"), [("hover_image", []),
                                                ("land_pad", ["--workers", "1"])])
def test_quick_variant_flies_every_row_and_keeps_its_direction(bench, workers, capsys):
    assert main(["bench", bench, "--quick", "--json", *workers]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["quick"]
    assert result["seeds"] == 1
    assert set(result["scenarios"]["default"]["runs"]) == set(down.BENCHES[bench].rows)
    assert down.quick_checks(result) == []
