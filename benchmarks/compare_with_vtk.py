"""Side-by-side pictures and PSNR: VolSR's ray caster vs VTK's vtkGPUVolumeRayCastMapper.

For each scene, one image: VolSR | VTK GPU mapper | |difference| x 4, shaded and unshaded.

    python benchmarks/compare_with_vtk.py [--data ../shared/data/volumes] [--size 320]
                                          [--out docs/images/renderer_vs_vtk.png]
"""
from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

import numpy as np
from PIL import Image

from volsr_core.atomic import atomic_write
from volsr_core.hosts.vtk_reference import VtkVolumeRenderer
from volsr_core.io import make_phantom
from volsr_core.render import RayCaster
from volsr_core.scene import Camera, Volume, get_preset

REPO = Path(__file__).resolve().parents[1]


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    return float(10 * np.log10(1.0 / max(np.mean((a - b) ** 2), 1e-12)))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data" / "volumes")
    parser.add_argument("--size", type=int, default=320)
    parser.add_argument("--out", type=Path, default=REPO / "docs" / "images" / "renderer_vs_vtk.png")
    args = parser.parse_args()
    scenes = [("phantom", Volume.from_record(make_phantom()), get_preset("CT-Phantom")),
              ("CT_AVM", Volume.load(args.data / "CT_AVM.nii.gz"), get_preset("CT-AAA").placed_on(0.0, 446.0))]
    rows = []
    for name, volume, tf in scenes:
        camera = Camera.framing(volume.bounds, direction=(0.4, 1.0, -0.3)).zoom(1.5).reset_clipping_range(volume.bounds)
        for label, scene_tf in (("shaded", tf), ("unshaded", replace(tf, shade=False, gradient_opacity=None))):
            ours = RayCaster(volume, scene_tf).render(camera, args.size).color
            host = VtkVolumeRenderer(volume, scene_tf, args.size, args.size, mapper="gpu")
            theirs = host.render(camera)
            host.close()
            print(f"{name:8s} {label:9s} PSNR VolSR vs VTK GPU mapper: {psnr(ours, theirs):.1f} dB")
            rows.append(np.concatenate([ours, theirs, np.clip(4 * np.abs(ours - theirs), 0, 1)], axis=1))
    picture = (np.concatenate(rows, axis=0) * 255).round().astype(np.uint8)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_write(args.out) as fh:
        Image.fromarray(picture).save(fh, format="PNG", optimize=True)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
