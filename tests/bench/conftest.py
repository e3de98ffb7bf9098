"""The load average at the start and end of a ``make bench`` run, kept in the JSON's machine info.

The development machine is shared, so every time in the generated pages is read beside the load it
was measured under (tools/bench_tables.py prints both).
"""

from __future__ import annotations

import os
import time

# this conftest is loaded when the run starts, before any benchmark
_START = {"time_utc": time.strftime("%Y-%m-%d %H:%M:%S", time.gmtime()), "load": list(os.getloadavg())}


def pytest_benchmark_update_machine_info(config, machine_info):
    """Called once, when the JSON is written at the end of the run. The JSON is committed: no host name."""
    machine_info.pop("node", None)
    machine_info["load_average"] = {
        "start": _START, "end": {"time_utc": time.strftime("%Y-%m-%d %H:%M:%S", time.gmtime()),
                                 "load": list(os.getloadavg())}}
