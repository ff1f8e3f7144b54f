"""The screenshots in docs/hosts-vtk.md and docs/pyvista.md: CT_AVM drawn by VolSR inside VTK and PyVista.

Real offscreen (EGL) runs of the host adapters, CT-AAA placed on 0..446, 512x384, with the hosts' default
model (VolSR XS 2x, from 256x192) unless ``--model`` names one:

    VTK_DEFAULT_OPENGL_WINDOW=vtkEGLRenderWindow python benchmarks/host_screenshots.py \
        [--model PATH | --model untrained] [--data ../shared/data/volumes] [--size 512x384] [--out docs/images]

``--model`` defaults to none, the hosts' own default; ``untrained`` exports the small
untrained network the tests use (the pictures then show the plumbing, not the quality).
Writes hosts_vtk.png and pyvista.png and prints the timings.
"""
from __future__ import annotations

import argparse
import os
import tempfile
from pathlib import Path

import numpy as np

os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")

REPO = Path(__file__).resolve().parents[1]
DIRECTION = (0.5, 1.0, -0.35)  # anterior, from the patient's left and from below


def untrained_model(folder: Path) -> Path:
    import torch

    from volsr_core.runtime.export import export_onnx
    from volsr_core.sr.network import SuperResolutionNet, variant_config

    torch.manual_seed(0)
    net = SuperResolutionNet(variant_config("S", 4, 0, recurrent=True)).eval()
    with torch.no_grad():
        for p in net.parameters():
            p.add_(torch.randn_like(p) * 0.05)
    return export_onnx(net, folder / "untrained_s4.onnx")


def save_png(pixels: np.ndarray, path: Path) -> None:
    from PIL import Image

    from volsr_core.atomic import atomic_write

    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_write(path) as fh:
        Image.fromarray(pixels).save(fh, format="PNG", optimize=True)
    print(f"wrote {path} ({path.stat().st_size // 1024} KiB)")


def vtk_screenshot(volume, tf, model, size, frames: int) -> np.ndarray:
    from volsr_core.hosts.vtk_adapter import VolSRPostProcess
    from volsr_core.scene.vtk_bridge import read_window
    from volsr_core.hosts.vtk_reference import VtkVolumeRenderer
    from volsr_core.scene.vtk_bridge import apply_camera
    from volsr_core.scene import Camera

    host = VtkVolumeRenderer(volume, tf, *size)
    camera = host.renderer.GetActiveCamera()
    apply_camera(camera, Camera.framing(volume.bounds, direction=DIRECTION, aspect=size[0] / size[1]).zoom(1.2))
    camera.Azimuth(-2.0 * frames)
    adapter = VolSRPostProcess(host.renderer, host.actor, volume, model)
    for _ in range(frames):  # a short orbit, so the picture shows a frame with history
        camera.Azimuth(2.0)
        host.window.Render()
    print(f"VTK: {adapter.frames} frames, last {adapter.pipeline.last_timings['total_ms']:.0f} ms "
          f"(render {adapter.pipeline.last_timings['render_ms']:.0f} ms)")
    pixels = read_window(host.window)
    host.close()
    return pixels


def pyvista_screenshot(volume, model, size, frames: int) -> np.ndarray:
    import pyvista as pv

    from volsr_core.hosts.pyvista import add_sr_volume

    plotter = pv.Plotter(off_screen=True, window_size=size)
    adapter = add_sr_volume(plotter, volume, transfer_function="CT-AAA", clim=(0, 446), model=model)
    plotter.camera_position = "xz"
    plotter.camera.elevation = 15
    plotter.camera.azimuth = 30 - 2 * frames
    plotter.show(auto_close=False)
    for _ in range(frames - 1):
        plotter.camera.azimuth += 2
        plotter.render()
    pixels = plotter.screenshot(return_img=True)
    print(f"PyVista: {adapter.frames} frames, last {adapter.pipeline.last_timings['total_ms']:.0f} ms")
    plotter.close()
    return pixels


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--model", default=None,
                        help="an .onnx/.pt file, 'untrained', or none for the hosts' default (XS 2x)")
    parser.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data" / "volumes")
    parser.add_argument("--size", default="512x384")
    parser.add_argument("--frames", type=int, default=6)
    parser.add_argument("--out", type=Path, default=REPO / "docs" / "images")
    args = parser.parse_args()
    size = tuple(int(v) for v in args.size.lower().split("x"))

    from volsr_core.scene import Volume, get_preset

    with tempfile.TemporaryDirectory() as scratch:
        if args.model == "untrained":
            model = untrained_model(Path(scratch))
        else:
            model = Path(args.model) if args.model else None
        volume = Volume.load(args.data / "CT_AVM.nii.gz")
        tf = get_preset("CT-AAA").placed_on(0.0, 446.0)
        save_png(vtk_screenshot(volume, tf, model, size, args.frames), args.out / "hosts_vtk.png")
        save_png(pyvista_screenshot(volume, model, size, args.frames), args.out / "pyvista.png")


if __name__ == "__main__":
    main()
