"""Per volume of one ``volsr bench`` run: where each temporal method lies against the native + bilinear curve, what it
gains over the bilinear upscale of its own LR size, and where its ms go (the tables of docs/performance.md's Results).

    python benchmarks/bench_volume_table.py docs/bench/1024-2deg [docs/bench/512-2deg ...]

A table per run, a column per volume. "vs curve": a method's PSNR less the curve's at its time (issue 12's target 2
asks ≥ +0.5 dB of every VolSR row; :func:`~volsr_core.apps.bench.report.check_targets`, TAAU's rows measured the same
way), with its PSNR and median total ms; for an XS row short of the margin, the time at which its PSNR would meet it;
"− 1/K size + bilinear": its PSNR less that of the native render of its own LR size stretched bilinearly (target 3 for
TAAU); then the ms after the LR render and the LR render's ms, by the size rendered at (TAAU, XS and the S U-Net of
that scale). Read from bench.json alone.
"""
from __future__ import annotations

import argparse
import json
import re
from pathlib import Path
from typing import Callable

from volsr_core.apps.bench.report import TARGET_MARGIN_DB, bilinear_curve, curve_psnr_at, curve_time_for


def _rows_by_scene(rows: list[dict]) -> dict[str, dict[str, dict]]:
    """Scene -> label -> row, the scenes in the run's order."""
    scenes: dict[str, dict[str, dict]] = {}
    for r in rows:
        scenes.setdefault(r["volume"], {})[r["label"]] = r
    return scenes


def _temporal_labels(rows: list[dict]) -> list[str]:
    """TAAU's rows by scale, then XS's, then the other VolSR rows, each by the size they render at."""
    def key(r: dict) -> tuple:
        group = 0 if r["method"] == "taau" else 1 if r["variant"] == "XS" else 2
        return group, r["scale"], r.get("stretch", 1), str(r["variant"])
    temporal = [r for r in rows if r["method"] in ("taau", "volsr") and r["psnr"] is not None]
    return list(dict.fromkeys(r["label"] for r in sorted(temporal, key=key)))


def _curve(found: dict[str, dict]) -> tuple[list[float], list[float]]:
    curve = bilinear_curve(list(found.values()))
    return [r["ms_total"] for r in curve], [r["psnr"] for r in curve]


def _vs_curve(r: dict, found: dict[str, dict]) -> str:
    margin = r["psnr"] - curve_psnr_at(*_curve(found), r["ms_total"])
    return f"{margin:+.2f} ({r['psnr']:.2f} dB, {r['ms_total']:.0f} ms)"


def _time_needed(r: dict, found: dict[str, dict]) -> str:
    times, psnrs = _curve(found)
    if r["psnr"] - curve_psnr_at(times, psnrs, r["ms_total"]) >= TARGET_MARGIN_DB:
        return "met"
    needed = curve_time_for(times, psnrs, r["psnr"] - TARGET_MARGIN_DB)
    return f"≤ {needed:.1f} ({r['ms_total']:.1f})" if needed is not None else "at no time"


def _over_same_size(r: dict, found: dict[str, dict]) -> str:
    same = found.get(f"native 1/{r['scale']} size + bilinear")
    return f"{r['psnr'] - same['psnr']:+.2f}" if same else "–"


def _is_s_model(label: str, scale: int) -> bool:
    """Whether ``label`` is VolSR S at ``scale``, unstretched, on TAAU or in depth slabs ("VolSR S 4x in 2 slabs")."""
    return re.fullmatch(rf"VolSR S {scale}x( in \d+ slabs)?", label) is not None


def run_table(results: dict) -> list[str]:
    """The markdown lines of one run's table."""
    s = results["settings"]
    scenes = _rows_by_scene(results["rows"])
    names = [volume.split(".")[0] for volume in scenes]
    title = f"{s['size'][0]}², {s['degrees_per_frame']:g}°/frame"
    lines = [f"| {title} | " + " | ".join(names) + " |", "|---|" + "---:|" * len(names)]

    def line(name: str, cell: Callable[[dict[str, dict]], str]) -> None:
        """A line named ``name``: ``cell(a volume's rows by label)`` per volume; none where every cell is "–"."""
        cells = [cell(found) for found in scenes.values()]
        if any(c != "–" for c in cells):
            lines.append(f"| {name} | " + " | ".join(cells) + " |")

    def of(label: str, cell: Callable[[dict, dict[str, dict]], str]) -> Callable[[dict[str, dict]], str]:
        """``cell(label's row, the volume's rows)``, "–" on a volume without that row."""
        return lambda found: cell(found[label], found) if label in found else "–"

    line("native 1 spp", of("native 1 spp", lambda r, _: f"{r['psnr']:.2f} dB, {r['ms_total']:.0f} ms"))
    labels = _temporal_labels(results["rows"])
    for label in labels:
        line(f"{label}: vs curve", of(label, _vs_curve))
    for label in (lb for lb in labels if lb.startswith("VolSR XS")):
        line(f"{label}: ms for +{TARGET_MARGIN_DB} dB at its PSNR (its ms)", of(label, _time_needed))
    for label in labels:
        if label.startswith(("TAAU", "VolSR XS")) or _is_s_model(label, 4):  # the U-Nets' gain: one stands for them
            line(f"{label} − same LR size + bilinear", of(label, _over_same_size))
    factors = sorted({found[label]["scale"] for found in scenes.values() for label in labels if label in found})
    for factor in factors:
        at = [label for label in labels if label.startswith(("TAAU", "VolSR XS")) or _is_s_model(label, factor)]
        at = [label for label in at if any(found.get(label, {}).get("scale") == factor for found in scenes.values())]
        native = f"native 1/{factor} size + bilinear"
        line(f"1/{factor} size, ms after the LR render: {' / '.join(at)}",
             lambda found: " / ".join(f"{found[label]['ms_network']:.1f}" if label in found else "–" for label in at))
        line(f"1/{factor} size, LR render ms: {' / '.join([native] + at)}",
             lambda found: " / ".join(f"{found[label]['ms_render']:.1f}" if label in found else "–"
                                      for label in [native] + at))
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("folders", nargs="+", type=Path, help="folders holding a bench.json, a table each")
    for folder in parser.parse_args().folders:
        print("\n".join(run_table(json.loads((folder / "bench.json").read_text(encoding="utf-8")))) + "\n")


if __name__ == "__main__":
    main()
