"""Write what each shipped model costs per frame, from `volsr bench` runs, into its model card.

    python training/model_card_costs.py docs/bench/*/bench.json

For every shipped model (resources/models/models.json) the section "## Cost per frame" of its card
is replaced (or appended): per benchmark run and volume, the LR render, network and total ms per
frame (medians), the PSNR, and its distance to the native + bilinear curve at equal time (what the
same time buys by rendering fewer pixels; docs/performance.md). Cards are rewritten atomically.
"""
from __future__ import annotations

import argparse
import json
import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
MODELS = REPO / "resources" / "models"
SECTION = "## Cost per frame"


def cost_section(model_files: set[str], bench_paths: list[Path]) -> list[str]:
    """The card section for the model whose ONNX files (float32, and 8-bit where it ships) are named
    ``model_files``, from bench.json files (the distance to the curve is the one the run's own target check worked
    out, ``targets``)."""
    lines = [SECTION, "",
             "Medians over the timed frames of `volsr bench` (those after the warm-up in each of its timing passes "
             "over the orbit: 24 a method by default; ONNX Runtime, CPU, 2 threads, the 8-bit file where the model "
             "ships one, on the window of the frame "
             "where the volume shows (`StatefulUpscaler(skip_background=True)`), or for variant XS its "
             "numba filter kernel, on the project's "
             "2-core machine; the LR render is the ray caster's; \"K slabs\": rendered in K depth slabs, the layered "
             "TAAU before the model; \"+ bicubic Kx\": the model's image stretched by K, a point at K times its "
             "scale). \"vs curve\": PSNR minus that of native "
             "rendering at reduced size + bilinear at the same total time (positive: the model pays off).", "",
             "| run | volume | LR render ms | TAAU + network ms | total ms | PSNR dB | vs curve dB | native 1 spp |",
             "|---|---|---:|---:|---:|---:|---:|---|"]
    for path in bench_paths:
        bench = json.loads(path.read_text())
        settings = bench["settings"]
        run = f"{settings['size'][0]}², {settings['degrees_per_frame']:g}°/frame"
        for scene in dict.fromkeys(r["scene"] for r in bench["rows"]):
            rows = [r for r in bench["rows"] if r["scene"] == scene]
            native = next((r for r in rows if r["method"] == "native" and r["spp"] == 1), None)
            if native is None:
                continue
            points = bench["targets"][scene]["above_bilinear"]["points"]
            for mine in (r for r in rows if r["method"] == "volsr" and r["model"] in model_files):
                margin = next(p["margin_db"] for p in points if p["label"] == mine["label"])
                slabs = mine.get("slabs", 0)  # runs before the slabs were recorded had none
                stretch = mine.get("stretch", 1)  # and none was stretched
                how = (f", {slabs} slab{'' if slabs == 1 else 's'}" if slabs else "") \
                    + (f", + bicubic {stretch}x" if stretch > 1 else "")
                lines.append(f"| {run}{how} | {mine['volume']} | {mine['ms_render']:.1f} | {mine['ms_network']:.1f} | "
                             f"{mine['ms_total']:.1f} | {mine['psnr']:.2f} | {margin:+.2f} | "
                             f"{native['psnr']:.2f} dB in {native['ms_total']:.1f} ms |")
    sources = ", ".join(f"`{p.resolve().relative_to(REPO).as_posix()}`" for p in bench_paths)
    return lines + ["", f"From {sources}."]


def replace_section(card: str, section: list[str], heading: str = SECTION) -> str:
    """``card`` with its section ``heading`` (up to the next "## " heading or the end) replaced by ``section``, or
    ``section`` appended."""
    body = "\n".join(section) + "\n"
    match = re.search(rf"^{re.escape(heading)}\n.*?(?=^## |\Z)", card, flags=re.S | re.M)
    if match is None:
        return card.rstrip("\n") + "\n\n" + body
    return card[: match.start()] + body + ("\n" if match.end() < len(card) else "") + card[match.end():]


def main() -> None:
    from volsr_core.atomic import atomic_write

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("bench", type=Path, nargs="+", help="bench.json files written by volsr bench")
    args = parser.parse_args()
    for entry in json.loads((MODELS / "models.json").read_text())["models"]:
        card_path = MODELS / entry["files"]["card"]
        files = {entry["files"][kind] for kind in ("onnx", "onnx_int8") if kind in entry["files"]}
        card = replace_section(card_path.read_text(), cost_section(files, args.bench))
        with atomic_write(card_path, "w") as fh:
            fh.write(card)
        print(f"{card_path.relative_to(REPO)}: cost section from {len(args.bench)} runs")


if __name__ == "__main__":
    main()
