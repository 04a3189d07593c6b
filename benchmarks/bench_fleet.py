"""VDA 5050 vehicles on MQTT: how many run at >= 1x real time (embedded broker, Mosquitto),
and the latency from publishing an order to the state that shows it accepted.

python benchmarks/bench_fleet.py [--quick]   (same as ``agvsim bench --fleet --json``)
"""

import json
import sys

from agvsim.fleet.bench import fleet_benchmark

if __name__ == "__main__":
    print(json.dumps(fleet_benchmark(quick="--quick" in sys.argv, log=print), indent=2))
