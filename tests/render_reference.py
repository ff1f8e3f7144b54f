"""A straightforward float64 ray caster, one Python loop per ray, to check the kernels against.

It shares no code with volsr_core.render: rays come from Camera.ray, classification evaluates
the transfer function exactly (no LUT), and it never skips empty space.
"""
from __future__ import annotations

import math

import numpy as np

from volsr_core.scene import Camera, TransferFunction, Volume


def trilinear(vol: np.ndarray, p: np.ndarray) -> float:
    nz, ny, nx = vol.shape
    p = np.clip(p, 0.0, [nx - 1, ny - 1, nz - 1])
    i0 = np.minimum(np.floor(p).astype(int), [nx - 2, ny - 2, nz - 2])
    f = p - i0
    total = 0.0
    for dk in (0, 1):
        for dj in (0, 1):
            for di in (0, 1):
                w = (f[0] if di else 1 - f[0]) * (f[1] if dj else 1 - f[1]) * (f[2] if dk else 1 - f[2])
                total += w * float(vol[i0[2] + dk, i0[1] + dj, i0[0] + di])
    return total


def render_reference(volume: Volume, tf: TransferFunction, camera: Camera, width: int, height: int,
                     step: float, jitter=(0.0, 0.0), previous: Camera | None = None,
                     early_termination: float = 0.99, background=(0.0, 0.0, 0.0), motion_depth: str = "threshold",
                     depth_threshold: float = 0.5) -> dict[str, np.ndarray]:
    vol = volume.array.astype(np.float64)
    w2i = volume.world_to_index
    m = volume.direction @ np.diag(volume.spacing)
    grad_to_world = np.linalg.inv(m).T
    hi = np.array(volume.shape_xyz, dtype=float) - 1.0
    corners = volume.corners
    radius = 0.5 * np.linalg.norm(corners.max(0) - corners.min(0))
    right, up, fwd = camera.basis()
    depth_lo = (corners.mean(0) - camera.position) @ fwd - radius
    out = {k: np.zeros((height, width, c)) for k, c in
           (("color", 3), ("alpha", 1), ("depth", 1), ("max_rgba", 4), ("position", 3), ("motion", 2),
            ("motion_depth", 1))}
    for y in range(height):
        for x in range(width):
            px, py = x + 0.5 + jitter[0], y + 0.5 + jitter[1]
            o, d = camera.ray(px, py, width, height)
            cosv = d @ fwd
            t0, t1 = camera.clipping_range[0] / cosv, camera.clipping_range[1] / cosv
            oi = w2i[:3, :3] @ o + w2i[:3, 3]
            di = w2i[:3, :3] @ d
            for a in range(3):
                if abs(di[a]) < 1e-12:
                    if not 0 <= oi[a] <= hi[a]:
                        t0, t1 = 1.0, 0.0
                    continue
                ta, tb = sorted(((0 - oi[a]) / di[a], (hi[a] - oi[a]) / di[a]))
                t0, t1 = max(t0, ta), min(t1, tb)
            color, acc, best, best_rgba = np.zeros(3), 0.0, 0.0, np.zeros(4)
            t_best = ((camera.focal_point - camera.position) @ fwd) / cosv
            t_cross, sum_w, sum_wt = None, 0.0, 0.0
            if t0 <= t1:
                for k in range(int(math.floor((t1 - t0) / step)) + 1):
                    t = t0 + k * step
                    p = oi + t * di
                    v = trilinear(vol, p)
                    a = float(tf.opacity_at(v))
                    a = 1.0 - (1.0 - min(max(a, 0.0), 1.0)) ** (step / tf.scalar_opacity_unit_distance)
                    rgb = np.clip(tf.color_at(v), 0, 1)
                    if a <= 0:
                        continue
                    g_idx = np.array([trilinear(vol, p + e) - trilinear(vol, p - e) for e in np.eye(3)]) * 0.5
                    g = grad_to_world @ g_idx
                    gmag = float(np.linalg.norm(g))
                    a *= float(tf.gradient_opacity_at(gmag))
                    if tf.shade:
                        ndotl = abs(g @ d) / gmag if gmag > 1e-6 else 1.0
                        rgb = np.minimum(rgb * (tf.ambient + tf.diffuse * ndotl)
                                         + tf.specular * ndotl ** tf.specular_power, 1.0)
                    if a > best:
                        best, best_rgba, t_best = a, np.append(rgb, a), t
                    color += (1 - acc) * a * rgb
                    sum_w, sum_wt = sum_w + (1 - acc) * a, sum_wt + (1 - acc) * a * t
                    acc += (1 - acc) * a
                    if t_cross is None and acc >= depth_threshold:
                        t_cross = t
                    if acc >= early_termination:
                        break
            pos = o + t_best * d
            out["color"][y, x] = color + (1 - acc) * np.asarray(background)
            out["alpha"][y, x] = acc
            out["max_rgba"][y, x] = best_rgba
            out["position"][y, x] = pos
            out["depth"][y, x] = np.clip(((pos - camera.position) @ fwd - depth_lo) / (2 * radius), 0, 1) if best > 0 else 1.0
            t_motion = t_best
            if motion_depth == "threshold" and t_cross is not None:
                t_motion = t_cross
            elif motion_depth == "mean" and sum_w > 0:
                t_motion = sum_wt / sum_w
            mpos = o + t_motion * d
            out["motion_depth"][y, x] = np.clip(((mpos - camera.position) @ fwd - depth_lo) / (2 * radius), 0, 1) \
                if best > 0 else 1.0
            if previous is not None:
                out["motion"][y, x] = previous.world_to_pixel(mpos, width, height) - np.array([px, py])
    out["alpha"] = out["alpha"][..., 0]
    out["depth"] = out["depth"][..., 0]
    out["motion_depth"] = out["motion_depth"][..., 0]
    return out
