#!/usr/bin/env python3
"""The yardstick's yardstick: penumbra's `reference` against Mitsuba 3, an independent
renderer, on real models (docs/measuring.md, "Is the reference right?").

For each model, penumbra renders it staged on a floor with its fitted camera and light
(`penumbra render JOB --timings-json`, which reports the staging used); this script builds the
same scene for Mitsuba from that staging — the model's triangles in world space (trimesh
flattens the glTF node tree), each material's base colour factor, the floor, the light as a
one-sided emitting rectangle, the camera — and renders direct light only with emitter
sampling (`direct`, no BSDF samples: the same integral as contract §1, by ray tracing rather
than depth maps). It then reports, over the reference's penumbra and the whole frame, how far
penumbra's reference lies from Mitsuba's image.

Mitsuba's visibility is read from its image through penumbra's own unshadowed colour
(`C_ref / V_ref` wherever V_ref ≥ 0.05: the same E0 and albedo), so the figure measures the
shadows alone. Pixels on a depth edge are left out (Mitsuba averages over the pixel, penumbra
takes its centre), and so are textured materials (choose models without textures).

Usage (from a virtual environment with mitsuba, trimesh, numpy, OpenEXR):
    python tools/yardstick/mitsuba_check.py --penumbra target/release/penumbra MODEL.glb ...
"""

import argparse
import json
import os
import subprocess
import sys

import numpy as np


def read_exr(path):
    import OpenEXR
    channels = {}
    for part in OpenEXR.File(path).parts:
        for name, channel in part.channels.items():
            channels[name] = channel.pixels
    return channels


def penumbra_reference(binary, model, size, samples, resolution, work):
    """penumbra's reference EXR channels and the staging its answer reports."""
    job = {
        'scene': {'path': os.path.abspath(model), 'floor': True},
        'method': {'name': 'reference', 'samples': samples, 'resolution': resolution},
        'output': {'width': size[0], 'height': size[1], 'format': 'exr'},
    }
    job_path, exr_path, answer_path = (os.path.join(work, name) for name in ('job.json', 'reference.exr', 'answer.json'))
    with open(job_path, 'w') as f:
        json.dump(job, f)
    subprocess.run([binary, 'render', job_path, '-o', exr_path, '--timings-json', answer_path],
                   check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return read_exr(exr_path), json.load(open(answer_path))['staging']


def linear_base_color(material):
    """A trimesh material's glTF base colour factor (linear RGB; 1 where there is none)."""
    factor = getattr(material, 'baseColorFactor', None)
    if factor is None:
        return [1.0, 1.0, 1.0]
    factor = np.asarray(factor, dtype=np.float64)
    if factor.dtype.kind in 'iu' or factor.max() > 1.0:  # trimesh keeps factors as bytes
        factor = factor / 255.0
    return [float(c) for c in factor[:3]]


def mitsuba_scene(mi, model, staging, size, spp):
    """The Mitsuba scene for penumbra's staging of `model`."""
    import trimesh
    T = mi.ScalarTransform4f
    loaded = trimesh.load(model, force='scene', process=False)
    scene = {'type': 'scene', 'integrator': {'type': 'direct', 'emitter_samples': 1, 'bsdf_samples': 0}}
    corners = []
    for k, node in enumerate(loaded.graph.nodes_geometry):
        transform, name = loaded.graph[node]
        mesh = loaded.geometry[name]
        if len(getattr(mesh, 'faces', [])) == 0:
            continue
        faces = np.asarray(mesh.faces, dtype=np.uint32)
        positions = trimesh.transformations.transform_points(mesh.vertices, transform).astype(np.float32)
        corners += [positions.min(axis=0), positions.max(axis=0)]
        # The file's own normals (trimesh keeps them in its cache), as penumbra reads them: a
        # mesh without them, or with one zero or not finite, is shaded flat (`add_mesh`).
        normals = mesh._cache.cache.get('vertex_normals')
        if normals is None or not np.all(np.isfinite(normals)) or np.any(np.linalg.norm(normals, axis=1) < 1e-6):
            positions = positions[faces.reshape(-1)]
            tri = positions.reshape(-1, 3, 3)
            face = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
            face /= np.maximum(np.linalg.norm(face, axis=1, keepdims=True), 1e-30)
            normals = np.repeat(face, 3, axis=0).astype(np.float32)
            faces = np.arange(len(positions), dtype=np.uint32).reshape(-1, 3)
        else:
            linear = np.linalg.inv(transform[:3, :3]).T
            normals = np.asarray(normals, dtype=np.float64) @ linear.T
            normals = (normals / np.linalg.norm(normals, axis=1, keepdims=True)).astype(np.float32)
        albedo = linear_base_color(getattr(mesh.visual, 'material', None))
        props = mi.Properties()
        props['bsdf'] = mi.load_dict({'type': 'twosided', 'bsdf': {'type': 'diffuse', 'reflectance': {'type': 'rgb', 'value': albedo}}})
        shape = mi.Mesh(f'mesh{k}', len(positions), len(faces), props=props, has_vertex_normals=True)
        params = mi.traverse(shape)
        params['vertex_positions'] = mi.Float(positions.ravel())
        params['vertex_normals'] = mi.Float(normals.ravel())
        params['faces'] = mi.UInt32(faces.ravel())
        params.update()
        scene[f'mesh{k}'] = shape
    lo, hi = np.min(corners, axis=0), np.max(corners, axis=0)
    # The floor: penumbra's `Scene::with_floor`, a square reaching `margin` bounding radii past
    # the bounds, at the height the staging reports.
    floor = staging['floor']
    radius = max(float(np.linalg.norm((hi - lo) * 0.5)), 1e-3)
    reach = floor['margin'] * radius
    (x0, z0), (x1, z1) = (lo[0] - reach, lo[2] - reach), (hi[0] + reach, hi[2] + reach)
    y = floor['height']
    scene['floor'] = {
        'type': 'rectangle',
        'to_world': T([[(x1 - x0) / 2, 0, 0, (x0 + x1) / 2], [0, 0, 1, y], [0, -(z1 - z0) / 2, 0, (z0 + z1) / 2], [0, 0, 0, 1]]),
        'bsdf': {'type': 'twosided', 'bsdf': {'type': 'diffuse', 'reflectance': {'type': 'rgb', 'value': floor['albedo']}}},
    }
    # The light (contract §1): n = direction, u = up made square to it, r = u × n; a one-sided
    # rectangle, whose local +z Mitsuba emits along.
    light = staging['light']
    assert light['image'] == {'builtin': 'white'}, 'the check compares under a white light'
    n = np.asarray(light['direction'], dtype=np.float64)
    n /= np.linalg.norm(n)
    up = np.asarray(light['up'], dtype=np.float64)
    u = up - up.dot(n) * n
    u /= np.linalg.norm(u)
    r = np.cross(u, n)
    (w, h), c = light['size'], light['center']
    scene['light'] = {
        'type': 'rectangle',
        'to_world': T([[r[i] * w / 2, u[i] * h / 2, n[i], c[i]] for i in range(3)] + [[0, 0, 0, 1]]),
        'emitter': {'type': 'area', 'radiance': {'type': 'rgb', 'value': [light['intensity']] * 3}},
    }
    camera = staging['camera']
    scene['sensor'] = {
        'type': 'perspective',
        'fov': camera['fov_y_deg'],
        'fov_axis': 'y',
        'near_clip': camera['near'],
        'far_clip': camera['far'],
        'to_world': T().look_at(origin=camera['eye'], target=camera['target'], up=camera['up']),
        'film': {'type': 'hdrfilm', 'width': size[0], 'height': size[1], 'rfilter': {'type': 'box'}, 'pixel_format': 'rgb'},
        'sampler': {'type': 'independent', 'sample_count': spp},
    }
    return mi.load_dict(scene)


def edges(values, tolerance):
    """Pixels with a 4-neighbour whose value differs by more than `tolerance` relative to the
    smaller of the two (or that is not finite)."""
    edge = np.zeros(values.shape[:2], dtype=bool)
    for axis in (0, 1):
        for shift in (1, -1):
            other = np.roll(values, shift, axis=axis)
            with np.errstate(invalid='ignore'):
                close = np.abs(other - values) <= tolerance * np.minimum(np.abs(values), np.abs(other))
            edge |= ~(close if close.ndim == 2 else np.all(close, axis=-1))
    return edge


def compare(reference, halves):
    """penumbra's reference against Mitsuba's image (the mean of two independent halves):
    visibility error over the penumbra and colour error over the frame, away from depth and
    shading edges (Mitsuba averages over the pixel, penumbra takes its centre); and Mitsuba's
    own noise, from the two halves: the error the comparison cannot see below."""
    rgba, v_ref, depth = reference['RGBA'], reference['visibility'], reference['depth']
    color = rgba[..., :3]
    covered = rgba[..., 3] > 0
    with np.errstate(divide='ignore', invalid='ignore'):
        unshadowed = np.where(v_ref >= 0.05, color / np.maximum(v_ref, 1e-6), np.nan)
    inside = covered & ~edges(np.where(np.isfinite(depth), depth, np.inf), 0.01) & ~edges(np.nan_to_num(unshadowed, nan=np.inf), 0.05)
    penumbra = inside & np.any((v_ref > 1e-4) & (v_ref < 1 - 1e-4), axis=-1)
    usable = penumbra & np.all(v_ref >= 0.05, axis=-1) & np.all(unshadowed > 1e-6, axis=-1)
    mitsuba = 0.5 * (halves[0] + halves[1])
    with np.errstate(divide='ignore', invalid='ignore'):
        visibility = [image / unshadowed for image in (mitsuba, *halves)]
    mae = lambda a, b: float(np.abs(a - b)[usable].mean()) if usable.any() else float('nan')
    return {
        'penumbra_pixels': int(penumbra.sum()),
        'penumbra_pixels_compared': int(usable.sum()),
        'visibility_mae_penumbra': mae(visibility[0], v_ref),
        # The halves differ by twice the full image's noise (in standard deviation).
        'mitsuba_noise_mae_penumbra': mae(visibility[1], visibility[2]) / 2,
        'color_relative_mae_frame': float(np.abs(mitsuba - color)[inside].mean() / max(color[inside].mean(), 1e-12)),
    }


def main():
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('models', nargs='+')
    parser.add_argument('--penumbra', default='target/release/penumbra')
    parser.add_argument('--size', default='320x240')
    parser.add_argument('--samples', type=int, default=1024, help="the reference's light samples")
    parser.add_argument('--resolution', type=int, default=2048, help="the reference's depth maps, texels per side")
    parser.add_argument('--spp', type=int, default=1024, help="Mitsuba's samples per pixel")
    parser.add_argument('--out', default='yardstick')
    args = parser.parse_args()
    size = tuple(int(x) for x in args.size.split('x'))
    import mitsuba as mi
    try:
        mi.set_variant('llvm_ad_rgb')
    except Exception:
        mi.set_variant('scalar_rgb')
    os.makedirs(args.out, exist_ok=True)
    rows = []
    for model in args.models:
        name = os.path.splitext(os.path.basename(model))[0]
        work = os.path.join(args.out, name)
        os.makedirs(work, exist_ok=True)
        reference, staging = penumbra_reference(args.penumbra, model, size, args.samples, args.resolution, work)
        scene = mitsuba_scene(mi, model, staging, size, args.spp // 2)
        halves = [np.asarray(mi.render(scene, seed=seed), dtype=np.float32)[..., :3] for seed in (1, 2)]
        mi.Bitmap(0.5 * (halves[0] + halves[1])).write(os.path.join(work, 'mitsuba.exr'))
        row = {'model': name, **compare(reference, halves)}
        rows.append(row)
        print(json.dumps(row), flush=True)
    with open(os.path.join(args.out, 'yardstick.json'), 'w') as f:
        json.dump({'variant': mi.variant(), 'samples': args.samples, 'resolution': args.resolution, 'spp': args.spp, 'rows': rows}, f, indent=1)


if __name__ == '__main__':
    sys.exit(main())
