"""One table of where every VolSR point of several ``volsr bench`` runs lies against the native + bilinear curve.

    python benchmarks/bench_summary.py docs/bench/512-2deg docs/bench/512-5deg docs/bench/1024-2deg docs/bench/1024-5deg
    python benchmarks/bench_summary.py --each-pass docs/bench-epyc/512-2deg docs/bench-epyc/1024-2deg

Per VolSR method (a row) and run (a column, in the order given): its distance to the curve at equal time over the
run's volumes, lowest to highest in dB, and on how many volumes it clears issue 12's margin (target 2,
:func:`~volsr_core.apps.bench.report.check_targets`, read again from each run's rows); with ``--each-pass``, for
runs timed in several passes over the orbit, also on how many it clears the margin in every pass and in at least one
(each pass's times against that pass's curve): the verdicts the machine's pace within the run could not move, and
those it could (runs made before aec6297 timed the scored pass with the bench's own bookkeeping: its pass is slow
there, docs/performance.md).
What docs/performance.md opens with; the runs' own bench.md give each volume.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

from volsr_core.apps.bench.report import TARGET_MARGIN_DB, check_targets


def margins(rows: list[dict]) -> dict[str, list[dict]]:
    """VolSR label -> its points of :func:`~volsr_core.apps.bench.report.check_targets` (``margin_db``, and
    ``margin_db_passes`` where the run has them) over the run's volumes, in the rows' order."""
    found: dict[str, list[dict]] = {}
    for scene in check_targets(rows).values():
        for point in scene["above_bilinear"]["points"]:
            found.setdefault(point["label"], []).append(point)
    return found


def render_factors(rows: list[dict]) -> dict[str, int]:
    """VolSR label -> how many times smaller per axis than the output its LR frame is (a row's ``scale``: a model's
    times its stretch)."""
    return {r["label"]: int(r["scale"]) for r in rows if r["method"] == "volsr"}


def cell(points: list[dict] | None, each_pass: bool = False) -> str:
    if not points:
        return "–"
    values = [p["margin_db"] for p in points]
    cleared = sum(v >= TARGET_MARGIN_DB for v in values)
    span = f"{min(values):+.2f}" if len(values) == 1 else f"{min(values):+.2f} to {max(values):+.2f}"
    passes = [p.get("margin_db_passes") for p in points]
    if not each_pass or not all(passes):
        return f"{span} ({cleared}/{len(values)})"
    every = sum(min(m) >= TARGET_MARGIN_DB for m in passes)
    some = sum(max(m) >= TARGET_MARGIN_DB for m in passes)
    return f"{span} ({cleared}/{len(values)}; every pass {every}, some pass {some})"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("folders", nargs="+", type=Path, help="folders holding a bench.json, one column each")
    parser.add_argument("--each-pass", action="store_true",
                        help="also count the volumes where a point clears the margin in every timing pass and in some")
    args = parser.parse_args()
    runs, factors = [], {}
    for folder in args.folders:
        results = json.loads((folder / "bench.json").read_text(encoding="utf-8"))
        settings = results["settings"]
        runs.append((f"{settings['size'][0]}², {settings['degrees_per_frame']:g}°/frame", margins(results["rows"])))
        factors.update(render_factors(results["rows"]))
    labels = sorted(dict.fromkeys(label for _, found in runs for label in found), key=lambda label: factors[label])
    print(f"| VolSR point (volumes ≥ +{TARGET_MARGIN_DB} dB) | renders at | " + " | ".join(name for name, _ in runs)
          + " |")
    print("|---|---|" + "---:|" * len(runs))
    for label in labels:
        cells = (cell(found.get(label), args.each_pass) for _, found in runs)
        print(f"| {label} | 1/{factors[label]} size | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
