"""``agvsim sweep`` over the fleet size: the master's figures as table columns, the row equal
to an in-process run of the same scenario, and the throughput plot's saturation point."""

from __future__ import annotations

from pathlib import Path

import pytest

from agvsim.experiments import run_sweep
from agvsim.master.config import GenerateConfig, MasterConfig
from agvsim.master.run import InProcessRun
from agvsim.master.sweep import saturation
from agvsim.scenario import load_scenario

ROOT = Path(__file__).resolve().parents[1]


def test_saturation_is_the_smallest_fleet_within_95_percent() -> None:
    sizes = [1, 2, 4, 8, 16]
    assert saturation(sizes, [50, 100, 180, 195, 200]) == 8  # 195 >= 0.95 * 200
    assert saturation(sizes, [50, 100, 190, 195, 200]) == 4  # 190 == 0.95 * 200
    assert saturation(sizes, [0, 0, 0, 0, 0]) is None
    assert saturation([3], [7.0]) == 3


@pytest.mark.slow
def test_sweep_over_fleet_size(tmp_path: Path) -> None:
    base = ROOT / "scenarios" / "warehouse_operations.yaml"
    sweep = tmp_path / "sizes.yaml"
    sweep.write_text(
        f"name: sizes\nbase: {base}\n"
        "vary:\n  master.fleet_size: [1, 3]\n"
        "cases:\n  busy: {master.generate: {rate_per_h: 600}, master.breakdowns: []}\n"
        "seeds: 1\nduration_s: 40\n"
    )
    res = run_sweep(sweep, out_dir=tmp_path / "out", workers=1)
    rows = res.table.to_pylist()
    assert [r["master.fleet_size"] for r in rows] == [1, 3]
    assert [r["vehicles"] for r in rows] == [1, 3]
    assert all(r["status"] == "completed" and r["master.collisions"] == 0 for r in rows)
    assert (tmp_path / "out" / "throughput.png").is_file()
    # the row is what the same scenario gives in-process
    sc = load_scenario(base)
    cfg = MasterConfig(fleet_size=3, generate=GenerateConfig(rate_per_h=600))
    sc2 = sc.model_copy(update={"master": cfg, "duration_s": 40.0})
    sc2._base_dir, sc2._source = sc._base_dir, sc._source
    run = InProcessRun(sc2, seed=0, master_period_s=0.25)
    run.run()
    s = run.summary()
    assert rows[1]["master.orders_completed"] == s["orders_completed"]
    assert rows[1]["master.orders_placed"] == s["orders_placed"] > 0
    assert rows[1]["master.utilisation.loaded"] == pytest.approx(s["utilisation"]["loaded"])


def test_fleet_size_beyond_the_fleet_is_refused(tmp_path: Path) -> None:
    sweep = tmp_path / "big.yaml"
    base = ROOT / "scenarios" / "warehouse_operations.yaml"
    sweep.write_text(f"base: {base}\nvary:\n  master.fleet_size: [21]\nduration_s: 5\n")
    from agvsim.experiments import SweepError

    with pytest.raises(SweepError, match=r"master.fleet_size: 21; the scenario has 1..20"):
        run_sweep(sweep, out_dir=tmp_path / "out", workers=1)
