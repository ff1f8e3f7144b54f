"""Rewrite the reports of ``volsr bench`` runs from their bench.json: the targets checked again, bench.md and bench.png
drawn again, by this version of ``volsr_core/apps/bench/report.py`` (the measurements, the rows, stay as they are).

    python benchmarks/bench_report.py docs/bench/*/

For a report that says more than the one its run wrote (since 2026-11-26: what time a point short of the margin
would need, ``ms_needed``); a run's numbers never change by it.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

from volsr_core.apps.bench.report import check_targets, write_outputs


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("folders", nargs="+", type=Path, help="folders holding a bench.json")
    for folder in parser.parse_args().folders:
        results = json.loads((folder / "bench.json").read_text(encoding="utf-8"))
        results["targets"] = check_targets(results["rows"])
        write_outputs(results, folder)
        print(f"rewrote {folder}")


if __name__ == "__main__":
    main()
