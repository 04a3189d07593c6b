"""What the input checks cost, and how fast a hostile input is refused.

Run ``python benchmarks/bench_input_checks.py``. Prints seconds (best of 3) for:

* reading a 998 x 1000 inline matrix (999,001 values, with ``yaml_max_nodes`` raised to
  1,000,000): the budget pass over the parser's events alone, and the whole ``load_yaml``;
* refusing a billion-laughs alias bomb (10^9 values expanded) and 50,000 nested brackets;
* ``measure_data`` over the same matrix as Python lists (the check ``parse_scenario`` runs
  on data that did not come through ``load_yaml``);
* ``parse_scenario`` of 10,000 robots (``max_robots``).

Prints numbers; does not gate.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable

from agvsim.safe_yaml import YamlInputError, YamlLimits, _measure, load_yaml, measure_data
from agvsim.scenario import parse_scenario


def best_of(fn: Callable[[], object], reps: int = 3) -> float:
    times = []
    for _ in range(reps):
        t0 = time.perf_counter()
        try:
            fn()
        except YamlInputError:
            pass
        times.append(time.perf_counter() - t0)
    return round(min(times), 4)


def main() -> dict[str, float]:
    matrix = "m:\n" + "".join("  - [" + ", ".join(["0"] * 1000) + "]\n" for _ in range(998))
    lines = ["a0: &a0 [lol, lol, lol, lol, lol, lol, lol, lol, lol, lol]"]
    lines += [f"a{i}: &a{i} [{', '.join([f'*a{i - 1}'] * 10)}]" for i in range(1, 9)]
    bomb = "\n".join(lines)
    deep = "[" * 50_000 + "]" * 50_000
    lists = [[0] * 1000 for _ in range(998)]
    big = YamlLimits(max_nodes=1_000_000)
    side = 101
    robots = [
        {"name": f"r{i}", "model": "differential", "pose": {"x_m": 2.0 * (i % side), "y_m": 0.0}}
        for i in range(10_000)
    ]
    scenario = {"world": {"maze": "thesis_c1"}, "robots": robots}
    return {
        "matrix_999001_values_budget_pass_s": best_of(lambda: _measure(matrix, "m", big)),
        "matrix_999001_values_load_yaml_s": best_of(lambda: load_yaml(matrix, "m", big), reps=1),
        "alias_bomb_refused_s": best_of(lambda: load_yaml(bomb, "bomb")),
        "nesting_50000_refused_s": best_of(lambda: load_yaml(deep, "deep")),
        "measure_data_999001_values_s": best_of(lambda: measure_data(lists, "m", big)),
        "parse_scenario_10000_robots_s": best_of(lambda: parse_scenario(scenario), reps=1),
    }


if __name__ == "__main__":
    print(json.dumps(main(), indent=2))
