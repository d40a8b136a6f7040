#!/usr/bin/env python3
"""Shadow rays per second: ltm's tracer against Embree, on the same rays.

For each scene, `bake/examples/shadow_rays.rs` takes the shadow rays that
`ltm bake` traces for evenly spaced rows (exactly those rays, in the bake's
order), replays them through ltm's tracer as the bake does
(`Scene::occluded_packet`, packets over obvhs's BVH) on one thread and on
all threads, and one at a time (`Scene::occluded`) on one thread, and
writes the rays, its answers and the traced triangles (world units). This script loads the same triangles into Mitsuba 3
(llvm variant, whose ray tracing is Embree), traces the same rays with
`Scene.ray_test` on one thread and on all threads, and reports both rates
(median of 5 runs after a warm-up), their ratio, and the fraction of rays
on which the two tracers agree (they differ only on rays that graze an edge
within float precision).

Scenes: assets/scenes/default.toml (bunny, ground and a sphere), and two
made here: a body with six thin limbs on a ground quad, and two interlocked
tori (genus 1) beside a sphere on a ground quad.

    python3 tools/validate/embree_rays.py [--size 64] [--face-res 16] [--max-rays 2000000]

Needs numpy and mitsuba (pip). Builds the example with cargo when missing.
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
sys.path.insert(0, HERE)
import mitsuba_texture as mt  # noqa: E402  (meshes and scene files)

EXAMPLE = os.path.join(ROOT, "target", "release", "examples", "shadow_rays")
CAM = dict(eye=[0.0, 1.4, 3.2], target=[0.0, 0.5, 0.0], fov=35.0)


def torus(big, small, nu=96, nv=32):
    """A torus of radii `big` and `small` about the y axis (genus 1)."""
    u, v = np.meshgrid(np.arange(nu) * 2 * np.pi / nu, np.arange(nv) * 2 * np.pi / nv,
                       indexing="ij")
    x = (big + small * np.cos(v)) * np.cos(u)
    z = (big + small * np.cos(v)) * np.sin(u)
    y = small * np.sin(v)
    verts = np.stack([x, y, z], -1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
    a, b = i * nv + j, ((i + 1) % nu) * nv + j
    c, d = ((i + 1) % nu) * nv + (j + 1) % nv, i * nv + (j + 1) % nv
    faces = np.concatenate([np.stack([a, b, c], -1), np.stack([a, c, d], -1)]).reshape(-1, 3)
    return verts, faces


def own_scenes(tmp):
    """The two scenes made here: (name, scene file)."""
    v, f = mt.limbs_mesh()
    mt.write_obj(os.path.join(tmp, "limbs.obj"), v, f)
    limbs = [dict(path=os.path.join(tmp, "limbs.obj"), scale=1.0,
                  translation=[0.0, float(-v[:, 1].min()), 0.0])]
    tv, tf = torus(0.35, 0.1)
    mt.write_obj(os.path.join(tmp, "torus.obj"), tv, tf)
    # The second torus stands upright through the first one's hole.
    uv = tv[:, [1, 0, 2]] + np.array([0.35, 0.0, 0.0])
    mt.write_obj(os.path.join(tmp, "torus2.obj"), uv, tf)
    sv, sf = mt.icosphere(4)
    mt.write_obj(os.path.join(tmp, "sphere.obj"), sv * 0.25, sf)
    rings = [dict(path=os.path.join(tmp, "torus.obj"), scale=1.0, translation=[-0.2, 0.45, 0.0]),
             dict(path=os.path.join(tmp, "torus2.obj"), scale=1.0, translation=[-0.2, 0.45, 0.0]),
             dict(path=os.path.join(tmp, "sphere.obj"), scale=1.0, translation=[0.6, 0.25, 0.3])]
    out = []
    for name, objects in (("limbs", limbs), ("rings", rings)):
        path = os.path.join(tmp, f"{name}.toml")
        with open(path, "w") as f:
            f.write(mt.scene_toml_objects(objects, CAM, 64, 16, 4, 1, True, None))
        out.append((name, path))
    return out


def ltm_rays(scene, args, out):
    """Runs the example on `scene`: its JSON report."""
    if not os.path.exists(EXAMPLE):
        subprocess.run(["cargo", "build", "--release", "-p", "ltm-bake", "--example",
                        "shadow_rays"], cwd=ROOT, check=True)
    cmd = [EXAMPLE, scene, str(args.size), str(args.size * 3 // 4), str(args.face_res),
           str(args.max_rays), out]
    return json.loads(subprocess.run(cmd, check=True, capture_output=True, text=True).stdout)


def embree_rays(mi, dr, out, threads):
    """Embree's rays/s on the example's rays (median of 5 after a warm-up)
    and the fraction of rays whose answer equals ltm's."""
    tris = np.fromfile(os.path.join(out, "world.f32"), dtype="<f4").reshape(-1, 9)
    rays = np.fromfile(os.path.join(out, "rays.f32"), dtype="<f4").reshape(-1, 6)
    ltm_hit = np.fromfile(os.path.join(out, "occluded.u8"), dtype=np.uint8).astype(bool)
    mesh = mi.Mesh("world", vertex_count=3 * len(tris), face_count=len(tris),
                   has_vertex_normals=False, has_vertex_texcoords=False)
    params = mi.traverse(mesh)
    params["vertex_positions"] = mi.Float(tris.reshape(-1).astype(np.float32))
    params["faces"] = mi.UInt32(np.arange(3 * len(tris), dtype=np.uint32))
    params.update()
    scene = mi.load_dict({"type": "scene", "world": mesh})
    ray = mi.Ray3f(mi.Point3f(*[mi.Float(np.ascontiguousarray(rays[:, k])) for k in range(3)]),
                   mi.Vector3f(*[mi.Float(np.ascontiguousarray(rays[:, k])) for k in range(3, 6)]))
    dr.eval(ray)
    dr.set_thread_count(threads)
    rates = []
    for i in range(6):
        start = time.perf_counter()
        hit = scene.ray_test(ray)
        dr.eval(hit)
        dr.sync_thread()
        if i > 0:
            rates.append(len(rays) / (time.perf_counter() - start))
    agree = float(np.mean(np.array(hit, dtype=bool) == ltm_hit))
    return float(np.median(rates)), agree


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--size", type=int, default=64, help="image width (height 3/4 of it)")
    ap.add_argument("--face-res", type=int, default=16)
    ap.add_argument("--max-rays", type=int, default=2_000_000)
    args = ap.parse_args()
    import drjit as dr
    import mitsuba as mi
    mi.set_variant("llvm_ad_rgb")
    cores = os.cpu_count()
    with tempfile.TemporaryDirectory() as tmp:
        scenes = [("default", os.path.join(ROOT, "assets/scenes/default.toml"))]
        scenes += own_scenes(tmp)
        print(f"| scene ({args.size}x{args.size * 3 // 4}, n = {args.face_res}) | rays | triangles "
              f"| ltm 1 thread (one ray at a time) | ltm 1 thread (packets) | Embree 1 thread "
              f"| ltm {cores} threads (packets) | Embree {cores} threads "
              f"| Embree/ltm (1 thread, packets) | answers equal |")
        print("|---|---|---|---|---|---|---|---|---|---|")
        for name, scene in scenes:
            out = os.path.join(tmp, name)
            r = ltm_rays(scene, args, out)
            one, one_agree = embree_rays(mi, dr, out, 1)
            all_, _ = embree_rays(mi, dr, out, cores)
            m = 1e6
            print(f"| {name} | {r['rays']} | {r['triangles']} "
                  f"| {r['single_rays_per_s_one_thread'] / m:.2f} M/s "
                  f"| {r['ltm_rays_per_s_one_thread'] / m:.2f} M/s | {one / m:.2f} M/s "
                  f"| {r['ltm_rays_per_s_all_threads'] / m:.2f} M/s | {all_ / m:.2f} M/s "
                  f"| {one / r['ltm_rays_per_s_one_thread']:.2f} | {100 * one_agree:.3f} % |",
                  flush=True)


if __name__ == "__main__":
    main()
