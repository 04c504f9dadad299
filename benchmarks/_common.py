"""Shared by the benchmark scripts: the machine record and the results file."""
from __future__ import annotations

import datetime as dt
import json
import os
import platform
import sys
from pathlib import Path

import numpy as np

import rscalib


def cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.lower().startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def machine_info(**extra) -> dict:
    """CPU, cores, versions and the load when the benchmark started (timings depend on it)."""
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else None
    return {"usable_cores": cores, "cpu_count": os.cpu_count(), "cpu_model": cpu_model(),
            "platform": platform.platform(), "python": sys.version.split()[0], "numpy": np.__version__,
            "rscalib": rscalib.__version__, "load_average_1min_at_start": load, **extra}


def write_results(path: Path, benchmark: str, info: dict, settings: dict, rows: list, table: str) -> None:
    result = {"benchmark": benchmark, "date": dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds"),
              "machine": info, "settings": settings, "results": rows, "table_markdown": table}
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(result, indent=2) + "\n")
    print(f"\nwritten {path}")
