"""``autopilot bench faults`` on one cell: its seeds fly in worker processes, each run's outcome
is counted, how long it will take is said before it starts."""

from autopilot.bench import faults


def test_one_cell_two_seeds_on_two_workers():
    said: list[str] = []
    logged: list[str] = []
    result = faults.run_bench(seeds=2, missions=["land_pad"], kinds=["battery_sag/critical"],
                              progress=logged.append, workers=2, announce=said.append)
    assert said[0].startswith("2 flights on 2 workers")
    (cell,) = result["cells"]
    assert (cell["mission"], cell["fault"], cell["runs"]) == ("land_pad", "battery_sag/critical", 2)
    assert cell["completed"] + cell["safe"] + cell["unsafe"] == 2
    assert cell["unsafe"] == 0
    assert result["workers"] == 2
    assert any("land_pad × battery_sag/critical, seed" in line for line in logged)
    assert "land_pad × battery_sag/critical:" in logged[-1]
    assert "2/2 done" in logged[-1]
