"""Runners for tests/test_sweep.py, importable by Dask workers: a real run, or an injected fault first."""
from __future__ import annotations

import json
import os
from pathlib import Path

from cosim.studies.sweep import execute_run


def faulty(run_dir: str, scenario_json: str) -> dict:
    """back_to_front raises every time; lowest_first kills its worker process on its first attempt."""
    strategy = json.loads(scenario_json)["controller"]["strategy"]
    if strategy == "back_to_front":
        raise RuntimeError("injected failure for back_to_front")
    marker = Path(run_dir).with_name(Path(run_dir).name + ".killed")
    if strategy == "lowest_first" and not marker.exists():
        marker.write_text(str(os.getpid()))
        os._exit(1)  # the worker dies with the run: Dask must reschedule it
    return execute_run(run_dir, scenario_json)
