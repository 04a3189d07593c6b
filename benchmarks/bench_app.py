"""The browser app with 10 robots carrying 240-beam lidars: frames/s and real-time factor.

python benchmarks/bench_app.py   (same as ``agvsim bench --app --json``)
"""

import json

from agvsim.bench_app import run_app_benchmark

if __name__ == "__main__":
    print(json.dumps(run_app_benchmark(log=print), indent=2))
