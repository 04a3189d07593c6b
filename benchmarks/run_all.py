"""Run every benchmark and print one JSON object (same as ``agvsim bench --json``).

python benchmarks/run_all.py [--quick]
"""

import json
import sys

from agvsim.bench import run_benchmarks

if __name__ == "__main__":
    print(json.dumps(run_benchmarks(quick="--quick" in sys.argv, log=print), indent=2))
