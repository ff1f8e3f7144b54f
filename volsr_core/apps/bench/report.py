"""What ``volsr bench`` reports: the targets (docs/performance.md), bench.md, bench.png and bench.json.

:func:`check_targets` checks the targets per volume from the benchmark rows (the native + bilinear
curve: :func:`curve_psnr_at`; the Pareto front: :func:`pareto_front`); :func:`write_outputs` writes
the three files atomically.
"""
from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from volsr_core.atomic import atomic_write
from volsr_core.errors import InputError

METHOD_ORDER = ("native", "bilinear", "taau", "volsr", "vtk")
TARGET_SCALE = 4              # target 1: VolSR at 4x reaches native 1-spp PSNR ...
TARGET_TIME_FRACTION = 1 / 2  # ... in at most this fraction of native 1-spp time
STRETCH_TIME_FRACTION = 1 / 3  # the earlier, stricter goal, still reported
TARGET_MARGIN_DB = 0.5        # target 2: every VolSR point at least this far above the native + bilinear curve


def pareto_front(times: Sequence[float], psnrs: Sequence[float]) -> list[int]:
    """Indices of the non-dominated points (less time and more PSNR are better), by time.

    A point is dominated when another one takes no more time and gives no less PSNR, and is
    strictly better in one of them; equal points do not dominate each other.
    """
    t = np.asarray(times, dtype=np.float64)
    p = np.asarray(psnrs, dtype=np.float64)
    keep = []
    for i in range(len(t)):
        dominated = np.any((t <= t[i]) & (p >= p[i]) & ((t < t[i]) | (p > p[i])))
        if not dominated:
            keep.append(i)
    return sorted(keep, key=lambda i: (t[i], -p[i]))


def curve_psnr_at(times: Sequence[float], psnrs: Sequence[float], at: float) -> float:
    """PSNR of the curve through (time, PSNR) points at time ``at``, linear in time; beyond its ends
    the end point's PSNR (the curve is not extrapolated)."""
    order = np.argsort(np.asarray(times, dtype=np.float64), kind="stable")
    return float(np.interp(at, np.asarray(times, dtype=np.float64)[order], np.asarray(psnrs, dtype=np.float64)[order]))


def curve_time_for(times: Sequence[float], psnrs: Sequence[float], psnr: float) -> float | None:
    """The time at which the curve through (time, PSNR) points first reaches ``psnr`` (linear in time between its
    points, as :func:`curve_psnr_at`): a point of PSNR p lies ``m`` dB above the curve at any time up to
    ``curve_time_for(times, psnrs, p - m)`` on a rising curve. None where the curve starts above ``psnr`` (at no time),
    ``math.inf`` where it never reaches it (at any time)."""
    order = np.argsort(np.asarray(times, dtype=np.float64), kind="stable")
    t, p = np.asarray(times, dtype=np.float64)[order], np.asarray(psnrs, dtype=np.float64)[order]
    if p[0] > psnr:
        return None
    for i in range(len(t)):
        if p[i] >= psnr:
            if i == 0:
                return float(t[0])
            return float(t[i - 1] + (psnr - p[i - 1]) * (t[i] - t[i - 1]) / (p[i] - p[i - 1]))
    return math.inf


def _scenes(rows: Sequence[dict]) -> list[str]:
    return list(dict.fromkeys(r["scene"] for r in rows))


def _native_1spp(rows: Sequence[dict]) -> dict | None:
    return next((r for r in rows if r["method"] == "native" and r["spp"] == 1), None)


def bilinear_curve(scene_rows: Sequence[dict]) -> list[dict]:
    """The rows of one scene that make the native + bilinear curve (target 2): native 1 spp, then every native at
    reduced size + bilinear, those with a PSNR; empty without native 1 spp."""
    native = _native_1spp(scene_rows)
    if native is None or native["psnr"] is None:
        return []
    return [native] + [r for r in scene_rows if r["method"] == "bilinear" and r["psnr"] is not None]


def check_targets(rows: Sequence[dict]) -> dict[str, dict[str, Any]]:
    """The issue's targets per scene, from benchmark rows.

    1. ``fast_4x``: some VolSR model at 4x reaches at least the PSNR of native full-size 1-spp
       rendering in at most 1/2 of that rendering's time (per-model details in ``points``, each
       also saying whether it did so in 1/3, ``within_third``, the stricter goal).
    2. ``above_bilinear``: every VolSR point lies at least 0.5 dB above the native + bilinear curve
       at equal time: the curve through native 1 spp (factor 1) and the bilinear rows, sorted by
       time, its PSNR interpolated linearly in time at the VolSR point's time (beyond the curve's
       time span: the end point's PSNR; such points are flagged ``outside``). A point short of the margin also
       says by what time it would have met it at its PSNR, ``ms_needed`` (:func:`curve_time_for`; None: at no
       time, the curve's fastest point lies above it less the margin). Where the rows hold the times of several
       passes over the orbit (``ms_total_passes``), each point also gives its margin in each pass, against the
       curve of that pass's times (``margin_db_passes``): how far the machine's pace moves the verdict within
       the run; the verdict itself is on the medians.

    ``met`` is True / False, or None when the rows cannot tell (no native 1 spp, no VolSR model).
    """
    result: dict[str, dict[str, Any]] = {}
    for scene in _scenes(rows):
        mine = [r for r in rows if r["scene"] == scene]
        native = _native_1spp(mine)
        volsr = [r for r in mine if r["method"] == "volsr" and r["psnr"] is not None]
        fast: dict[str, Any] = {"met": None, "points": []}
        above: dict[str, Any] = {"met": None, "points": []}
        if native is not None and native["psnr"] is not None:
            budget = native["ms_total"] * TARGET_TIME_FRACTION
            fast.update(native_psnr=native["psnr"], native_ms=native["ms_total"], budget_ms=round(budget, 4))
            for r in volsr:
                if r["scale"] == TARGET_SCALE:
                    ok = r["psnr"] >= native["psnr"] and r["ms_total"] <= budget
                    third = r["psnr"] >= native["psnr"] and r["ms_total"] <= native["ms_total"] * STRETCH_TIME_FRACTION
                    fast["points"].append({"label": r["label"], "psnr": r["psnr"], "ms_total": r["ms_total"],
                                           "met": bool(ok), "within_third": bool(third)})
            if fast["points"]:
                fast["met"] = any(p["met"] for p in fast["points"])
            curve = bilinear_curve(mine)
            times, psnrs = [r["ms_total"] for r in curve], [r["psnr"] for r in curve]
            for r in volsr:
                on_curve = curve_psnr_at(times, psnrs, r["ms_total"])
                point = {"label": r["label"], "psnr": r["psnr"], "ms_total": r["ms_total"],
                         "curve_psnr": round(on_curve, 4), "margin_db": round(r["psnr"] - on_curve, 4),
                         "outside": not min(times) <= r["ms_total"] <= max(times),
                         "met": bool(r["psnr"] >= on_curve + TARGET_MARGIN_DB)}
                if not point["met"]:
                    needed = curve_time_for(times, psnrs, r["psnr"] - TARGET_MARGIN_DB)
                    point["ms_needed"] = None if needed is None else round(needed, 4)
                passes = _margins_per_pass(curve, r)
                if passes:
                    point["margin_db_passes"] = passes
                above["points"].append(point)
            if above["points"]:
                above["met"] = all(p["met"] for p in above["points"])
        result[scene] = {"fast_4x": fast, "above_bilinear": above}
    return result


def _margins_per_pass(curve: Sequence[dict], point: dict) -> list[float] | None:
    """``point``'s distance (dB) to the curve through ``curve``'s rows in each timing pass: its time in pass p
    against the curve of the rows' times in pass p (their PSNRs are the scored pass's in every pass); None unless
    every row holds the same number (two or more) of finite pass times."""
    passes = [r.get("ms_total_passes") or [] for r in [point, *curve]]
    if len(passes[0]) < 2 or any(len(p) != len(passes[0]) or None in p for p in passes):
        return None
    psnrs = [r["psnr"] for r in curve]
    return [round(point["psnr"] - curve_psnr_at([p[k] for p in passes[1:]], psnrs, passes[0][k]), 4)
            for k in range(len(passes[0]))]


def _verdict(met: bool | None) -> str:
    return {True: "**met**", False: "**not met**", None: "not evaluated"}[met]


def target_lines(targets: dict[str, Any]) -> list[str]:
    """Human-readable verdicts for one scene's :func:`check_targets` entry (markdown)."""
    fast, above = targets["fast_4x"], targets["above_bilinear"]
    lines = []
    text = (f"1. VolSR at {TARGET_SCALE}x reaches at least native 1-spp PSNR in ≤ 1/2 of its time: "
            f"{_verdict(fast['met'])}")
    if "native_psnr" in fast:
        text += (f" (native 1 spp: {fast['native_psnr']:.2f} dB in {fast['native_ms']:.1f} ms; "
                 f"budget {fast['budget_ms']:.1f} ms)")
    if fast["met"] is None:
        text += f" - no VolSR model at {TARGET_SCALE}x was benchmarked"
    lines.append(text)
    lines += [f"   - {p['label']}: {p['psnr']:.2f} dB in {p['ms_total']:.1f} ms: {'yes' if p['met'] else 'no'}"
              f" (in ≤ 1/3: {'yes' if p['within_third'] else 'no'})" for p in fast["points"]]
    text = (f"2. Every VolSR point lies at least {TARGET_MARGIN_DB} dB above the native + bilinear curve at equal "
            f"time: {_verdict(above['met'])}")
    if above["met"] is None:
        text += " - no VolSR model was benchmarked"
    lines.append(text)
    lines += [f"   - {p['label']}: {p['psnr']:.2f} dB vs curve {p['curve_psnr']:.2f} dB at {p['ms_total']:.1f} ms "
              f"({p['margin_db']:+.2f} dB{', beyond the curve: its end point' if p['outside'] else ''}"
              f"{_each_pass(p)}): {'yes' if p['met'] else 'no' + _needed(p)}" for p in above["points"]]
    return lines


def _each_pass(point: dict[str, Any]) -> str:
    """A point's margins in each timing pass, for the verdict lines ("" for rows of one pass)."""
    margins = point.get("margin_db_passes")
    return "" if not margins else "; each pass " + " / ".join(f"{m:+.2f}" for m in margins)


def _needed(point: dict[str, Any]) -> str:
    """What a point short of the margin would need, at its PSNR, for the verdict lines."""
    needed = point.get("ms_needed", "absent")
    if needed == "absent":  # bench.json of an older version
        return ""
    if needed is None:
        return f" (at no time: the curve's fastest point is above {point['psnr'] - TARGET_MARGIN_DB:.2f} dB)"
    return f" (at its PSNR it needs ≤ {needed:.1f} ms: {point['ms_total'] - needed:.1f} ms less)"


def _sorted_rows(rows: Sequence[dict]) -> list[dict]:
    return sorted(rows, key=lambda r: (METHOD_ORDER.index(r["method"]), r["scale"], r["spp"], str(r["variant"]),
                                       r.get("stretch", 1)))


def _ms(v: float | None) -> str:
    return "-" if v is None else f"{v:.1f}"


def _passes(settings: dict[str, Any]) -> str:
    """How many passes over the orbit the times come from, for bench.md ("" for one: a run of an older version)."""
    passes = settings.get("timing_passes", 1)
    if passes == 1:
        return ""
    return (f" in {passes} passes over the orbit ({settings['timed_frames']} frames a method: the scored pass and "
            f"{passes - 1} more with fresh methods, timed only)")


def markdown_report(results: dict[str, Any]) -> str:
    """bench.md: settings, a table per scene with ratios to native 1 spp, and the target verdicts."""
    s = results["settings"]
    width, height = s["size"]
    lines = ["# VolSR benchmark: quality against time", "",
             f"{width}x{height} pixels; camera orbiting {s['frames']} frames of {s['degrees_per_frame']:g}° each; "
             f"quality (PSNR, SSIM against a {s['reference_spp']}-spp supersampled native rendering) averaged over "
             f"the {s['measured_frames']} frames after {s['warmup']} warm-up frames; times are medians over the same "
             f"frames{_passes(s)}. All methods in one run, interleaved frame by frame; onnxruntime "
             f"{s['onnxruntime_threads']} threads, numba {s['numba_threads']} threads, device {s['device']}. "
             f"Machine: {results['machine']['processor']}, {results['machine']['cpu_count']} CPUs"
             + (f" ({results['machine']['cpu']})" if results["machine"].get("cpu") else "")
             + f", {results['machine']['date']}.", "",
             "Render = ray casting (native and its reduced sizes: the colour alone, as VTK's renderer; TAAU and "
             "VolSR: every feature buffer, motion vectors too); network = what follows it (TAAU "
             "and the network for VolSR, the upscaling for bilinear and TAAU); total is the median of the per-frame "
             "sums, so it need not equal the two medians added. Time and ΔPSNR are relative to native full-size "
             "1-spp rendering.", ""]
    if any(r.get("stretch", 1) > 1 for r in results["rows"]):
        lines += ["\"VolSR ... + bicubic Kx\": the model's image at 1/K of the size, stretched to it by Keys' cubic "
                  "(a = -0.75; `Pipeline(..., stretch=K)`): a point at K times the model's scale, rendered at the "
                  "size of the others at that scale; the stretch is in its network ms.", ""]
    readback = [r["ms_readback"] for r in results["rows"] if r.get("ms_readback")]
    if readback:
        lines += [f"On the GPU every method makes its full-size image there (the bilinear stretch too, as VTK's) and "
                  f"its times end when the GPU is done; the image's copy to the host for scoring, {min(readback):.1f}-"
                  f"{max(readback):.1f} ms a frame (medians per method), is in none of them.", ""]
    if not results["models"]:
        lines += ["No VolSR model was benchmarked (no shipped model for the chosen variants and scales, and no "
                  "`--models-dir`).", ""]
    for scene in _scenes(results["rows"]):
        mine = [r for r in results["rows"] if r["scene"] == scene]
        native = _native_1spp(mine)
        passes = len(mine[0].get("ms_total_passes", [])) > 1  # each pass's median beside the pooled one
        lines += [f"## {scene}", "",
                  "| method | render ms | network ms | total ms |" + (" total ms, each pass |" if passes else "")
                  + " time / native 1 spp | PSNR dB | ΔPSNR dB | SSIM |",
                  "|---|---:|---:|---:|" + ("---:|" if passes else "") + "---:|---:|---:|---:|"]
        for r in _sorted_rows(mine):
            ratio = (f"{r['ms_total'] / native['ms_total']:.2f}" if native and native["ms_total"] and r["ms_total"]
                     is not None else "-")
            delta = (f"{r['psnr'] - native['psnr']:+.2f}" if native and native["psnr"] is not None
                     and r["psnr"] is not None else "-")
            psnr = "-" if r["psnr"] is None else f"{r['psnr']:.2f}"
            ssim = "-" if r["ssim"] is None else f"{r['ssim']:.4f}"
            each = f" {' / '.join(_ms(v) for v in r['ms_total_passes'])} |" if passes else ""
            lines.append(f"| {r['label']} | {_ms(r['ms_render'])} | {_ms(r['ms_network'])} | {_ms(r['ms_total'])} |"
                         f"{each} {ratio} | {psnr} | {delta} | {ssim} |")
        lines += ["", "Targets:", ""] + target_lines(results["targets"][scene]) + [""]
    return "\n".join(lines)


def plot(results: dict[str, Any], path: str | os.PathLike) -> Path:
    """bench.png: PSNR against ms per frame, one panel per scene, Pareto front marked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    scenes = _scenes(results["rows"])
    cols = min(3, max(1, len(scenes)))
    n_rows = math.ceil(len(scenes) / cols) if scenes else 1
    fig, axes = plt.subplots(n_rows, cols, figsize=(5.2 * cols, 4.2 * n_rows), squeeze=False)
    styles = {"native": ("o", "C0"), "bilinear": ("s", "C1"), "taau": ("^", "C2"), "vtk": ("D", "C7")}
    volsr_colours = {"XS": "C8", "S": "C3", "M": "C4", "L": "C5"}
    for ax, scene in zip(axes.flat, scenes):
        mine = [r for r in _sorted_rows(results["rows"]) if r["scene"] == scene
                and r["psnr"] is not None and r["ms_total"] is not None]
        native = _native_1spp(mine)
        curve = sorted(([native] if native else []) + [r for r in mine if r["method"] == "bilinear"],
                       key=lambda r: r["ms_total"])
        if curve:
            ax.plot([r["ms_total"] for r in curve], [r["psnr"] for r in curve], "-", color="C1", lw=1, alpha=0.6,
                    label="native + bilinear curve")
        seen = set()
        for r in mine:
            stretch = r.get("stretch", 1)  # a VolSR model's image stretched (runs before it: none)
            volsr_style = ("P" if stretch > 1 else "*", volsr_colours.get(r["variant"], "C6"))
            marker, colour = styles.get(r["method"], volsr_style)
            name = {"native": "native", "bilinear": "native reduced + bilinear", "taau": "TAAU", "vtk": r["label"]}.get(
                r["method"], f"VolSR {r['variant']}" + (" + bicubic" if stretch > 1 else ""))
            ax.plot(r["ms_total"], r["psnr"], marker, color=colour, ms=9 if r["method"] == "volsr" else 6,
                    label=None if name in seen else name)
            seen.add(name)
            short = {"native": f"{r['spp']} spp", "bilinear": f"1/{r['scale']}", "taau": f"{r['scale']}x",
                     "vtk": "VTK"}.get(r["method"], f"{r['variant']} {r['scale'] // stretch}x"
                                       + (f" + {stretch}x" if stretch > 1 else ""))
            ax.annotate(short, (r["ms_total"], r["psnr"]), textcoords="offset points", xytext=(4, 3), fontsize=7)
        front = [mine[i] for i in pareto_front([r["ms_total"] for r in mine], [r["psnr"] for r in mine])]
        if front:
            ax.plot([r["ms_total"] for r in front], [r["psnr"] for r in front], "--", color="k", lw=1.2,
                    label="Pareto front", zorder=0)
        ax.set_xscale("log")
        ax.xaxis.set_major_formatter(matplotlib.ticker.FuncFormatter(lambda v, _: f"{v:g}"))
        ax.xaxis.set_minor_formatter(matplotlib.ticker.FuncFormatter(
            lambda v, _: f"{v:g}" if f"{v:g}"[0] in "25" else ""))
        ax.tick_params(axis="x", which="minor", labelsize=7)
        ax.set_xlabel("ms per frame (median)")
        ax.set_ylabel("PSNR (dB)")
        ax.set_title(scene, fontsize=9)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7, loc="best")
    for ax in list(axes.flat)[len(scenes):]:
        ax.set_visible(False)
    fig.tight_layout()
    path = Path(path)
    with atomic_write(path) as fh:
        fig.savefig(fh, format="png", dpi=120)
    plt.close(fig)
    return path


def write_outputs(results: dict[str, Any], out_dir: str | os.PathLike) -> list[Path]:
    """bench.json, bench.md and bench.png in ``out_dir`` (created), each written atomically."""
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise InputError(out, "exists and is not a folder")
    out.mkdir(parents=True, exist_ok=True)
    with atomic_write(out / "bench.json", "w", encoding="utf-8") as fh:
        json.dump(results, fh, indent=1, allow_nan=False)
        fh.write("\n")
    with atomic_write(out / "bench.md", "w", encoding="utf-8") as fh:
        fh.write(markdown_report(results))
    plot(results, out / "bench.png")
    return [out / "bench.json", out / "bench.md", out / "bench.png"]
