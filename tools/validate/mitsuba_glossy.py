#!/usr/bin/env python3
"""Glossy materials by wavelet rotation (`ltm render --brdf`) against Mitsuba 3.

Issue 31's check "renders against Mitsuba 3": convex meshes with smooth
normals (nothing shadows them, so the unshadowed glossy part is the whole
answer), lit by a distant map, drawn by `ltm render --brdf SPEC --shading
glossy` and by Mitsuba's `direct` integrator with the matching BSDF.

Meshes (made here, not in assets/): `sphere` (a level-5 icosphere of
radius 0.5) and `egg` (the same sphere scaled to a 0.55 x 0.42 x 0.36
ellipsoid and turned), both with exact vertex normals written into the OBJ,
which both renderers interpolate.

Materials, each at GGX roughness alpha = 0.05, 0.1, 0.2 and 0.5:
- `conductor`: ltm `ggx:ALPHA,f0=1` against Mitsuba `roughconductor`
  (GGX, material "none": Fresnel 1). The two models are the same formula
  (GGX D, separable Smith G1, Fresnel 1), so the difference is what the
  rotation, the BRDF slices and the texture-space shading cost.
- `coat`: ltm `plastic:ALPHA,albedo=0,ior=1.5` against Mitsuba
  `roughplastic` (GGX, int_ior 1.5, diffuse_reflectance 0): the coat alone.
  Both take the exact dielectric Fresnel; the script also prints how far
  Schlick's approximation is from it for this index.
- `lambert`: ltm `lambert:0.8` against Mitsuba `diffuse` 0.8, once per map
  and mesh: the conventions check (map orientation, normals, units).

Lighting: the map is averaged over each texel of a cubemap of face
resolution `--light-n` (default 64), and written
back as a lat-long map whose pixels hold the texel their centre lies in;
Mitsuba's `envmap` and `ltm render --env` read that file, so both see the
same piecewise-constant lighting. Maps: `studio` and `courtyard` (assets/)
and `sun` (made here: a sky gradient, a ground and a sun of 2 degrees'
radius, 10^4 times brighter than the sky).

Per view: the relative L2 error over the pixels more than 1 px from a
silhouette, and the same with Mitsuba's noise (a second seed) removed in
quadrature.

`--rows image` draws each camera's own image rows instead: the mesh is
baked as an image-space file from that camera (`width` pixels square) and
shaded by `ltm relight --brdf SPEC --shading glossy`, which recovers the
eye from the file's surface records.

`--filters` renders each case once in Mitsuba and draws it four ways
against that render: image and texture rows, each with `--view-filter
nearest` and `bilinear` (docs/results/glossy.md, "Image rows, and the view
grid read bilinearly").

`--sweep` instead varies, for the sphere under `studio` with the conductor
at alpha = 0.1 and 0.2, one setting at a time from the defaults:
--brdf-keep, --normals, --glossy-terms and --glossy-n (ltm's other
settings at their defaults: `--glossy-n` follows the BRDF).

Usage:
  cargo build --release -p ltm-tools
  pip install mitsuba numpy
  python3 tools/validate/mitsuba_glossy.py --out /tmp/ltm-glossy
"""

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.normpath(os.path.join(HERE, "..", ".."))
sys.path.insert(0, HERE)
import mitsuba_compare as mc  # noqa: E402
import mitsuba_texture as mt  # noqa: E402

ALPHAS = [0.05, 0.1, 0.2, 0.5]
MAPS = ["studio", "courtyard", "sun"]
MESHES = ["sphere", "egg"]
CENTER = [0.0, 0.55, 0.0]
LAMBERT = 0.8
IOR = 1.5


# ------------------------------------------------------------------ meshes

def mesh_file(name, out, level=5):
    """An OBJ with exact vertex normals, in world space (centred at CENTER)."""
    v, f = mt.icosphere(level)
    if name == "sphere":
        p, nrm = 0.5 * v, v
    else:
        s = np.array([0.55, 0.42, 0.36])
        c, si = math.cos(0.6), math.sin(0.6)
        rot = np.array([[c, 0, si], [0, 1, 0], [-si, 0, c]]) @ \
            np.array([[1, 0, 0], [0, math.cos(0.4), -math.sin(0.4)],
                      [0, math.sin(0.4), math.cos(0.4)]])
        p = (v * s) @ rot.T
        nrm = (v / s) @ rot.T
    nrm = nrm / np.linalg.norm(nrm, axis=1, keepdims=True)
    p = p + np.array(CENTER)
    path = os.path.join(out, f"{name}.obj")
    with open(path, "w") as o:
        for q in p:
            o.write(f"v {q[0]:.7g} {q[1]:.7g} {q[2]:.7g}\n")
        for q in nrm:
            o.write(f"vn {q[0]:.7g} {q[1]:.7g} {q[2]:.7g}\n")
        for t in f:
            a, b, c_ = t + 1
            o.write(f"f {a}//{a} {b}//{b} {c_}//{c_}\n")
    return path


def image_scene_toml(mesh, cam, width):
    """An image-space bake of the mesh alone (no ground) from `cam`: its
    pixels' surface points are what `ltm relight --brdf` shades."""
    return f"""[camera]
eye = {list(cam['eye'])}
target = {list(cam['target'])}
fov = {cam['fov']}
width = {width}
height = {width}

[lighting]
face_res = 4
texel_samples = 1

[materials.clay]
type = "lambert"
albedo = [0.5, 0.5, 0.5]

[[meshes]]
path = "{mesh}"
material = "clay"
"""


def scene_toml(mesh, cam, size):
    """A texture-space bake of the mesh alone (no ground). Only its surface
    points are used (`--shading glossy`), so the transport is kept small."""
    return image_scene_toml(mesh, cam, 16) + f"""
[texture]
mesh = 0
size = {size}
parameterization = "sphere"
spp = 1
"""


# ------------------------------------------------------------------- maps

def sun_map(height=1024):
    """A sky gradient over a dark ground, and a sun of 2 degrees' radius at
    elevation 35 degrees, radiance 10^4 times the zenith's."""
    w = 2 * height
    u = (np.arange(w) + 0.5) / w
    v = (np.arange(height) + 0.5) / height
    phi, theta = np.meshgrid(2 * np.pi * u, np.pi * v, indexing="xy")
    d = np.stack([np.sin(theta) * np.sin(phi), np.cos(theta),
                  -np.sin(theta) * np.cos(phi)], axis=-1)
    up = d[..., 1]
    sky = np.where(up[..., None] > 0,
                   np.array([0.25, 0.45, 0.9]) * (0.4 + 0.6 * (1 - up[..., None])),
                   np.array([0.12, 0.1, 0.08]))
    el, az = math.radians(35), math.radians(120)
    sun = np.array([math.cos(el) * math.sin(az), math.sin(el), -math.cos(el) * math.cos(az)])
    disc = (d @ sun) > math.cos(math.radians(2.0))
    return sky + disc[..., None] * np.array([9000.0, 8000.0, 6500.0])


def lighting(mi, name, n, height, out):
    """The piecewise-constant lat-long file both renderers read, and the
    cubemap texels it holds."""
    if name == "sun":
        src = sun_map()
    else:
        path = os.path.join(ROOT, f"assets/envmaps/{name}.exr")
        src = np.maximum(np.array(mi.Bitmap(path)), 0.0)[..., :3].astype(np.float64)
    light = mc.texel_radiance(src, n, 8)
    env = mt.latlong_from_cubemap(light, n, height)
    path = os.path.join(out, f"env_{name}.exr")
    mi.Bitmap(env.astype(np.float32)).write(path)
    return path, env


# -------------------------------------------------------------- materials

def ltm_spec(material, alpha):
    return {"conductor": f"ggx:{alpha},f0=1",
            "coat": f"plastic:{alpha},albedo=0,ior={IOR}",
            "lambert": f"lambert:{LAMBERT}"}[material]


def mitsuba_bsdf(material, alpha):
    if material == "conductor":
        return {"type": "roughconductor", "distribution": "ggx", "alpha": alpha,
                "material": "none"}
    if material == "coat":
        return {"type": "roughplastic", "distribution": "ggx", "alpha": alpha,
                "int_ior": IOR, "ext_ior": 1.0, "nonlinear": False,
                "diffuse_reflectance": {"type": "rgb", "value": 0.0}}
    return {"type": "diffuse", "reflectance": {"type": "rgb", "value": LAMBERT}}


def fresnel_gap(ior):
    """Relative L2 difference of Schlick's Fresnel and the exact dielectric
    one over cos in (0, 1], uniformly weighted."""
    c = (np.arange(1000) + 0.5) / 1000
    f0 = ((ior - 1) / (ior + 1)) ** 2
    schlick = f0 + (1 - f0) * (1 - c) ** 5
    g = np.sqrt(ior ** 2 - 1 + c ** 2)
    exact = 0.5 * ((g - c) / (g + c)) ** 2 * (1 + ((c * (g + c) - 1) / (c * (g - c) + 1)) ** 2)
    return float(np.linalg.norm(schlick - exact) / np.linalg.norm(exact))


# -------------------------------------------------------------- rendering

def mitsuba_render(mi, args, mesh, cam, env, bsdf, seed):
    d = {"type": "scene",
         "integrator": {"type": "direct", "hide_emitters": True},
         "sensor": mt.sensor_dict(mi, cam, args.width, args.spp, sampler=args.sampler),
         "env": {"type": "envmap", "bitmap": mi.Bitmap(env.astype(np.float32))},
         "mesh": {"type": "obj", "filename": mesh, "face_normals": False, "bsdf": bsdf}}
    return np.array(mi.render(mi.load_dict(d), seed=seed), dtype=np.float64)[..., :3]


def ltm_render(args, ltm_file, env_path, cam, spec, out, extra=()):
    # A cache folder: ltm keeps one file per setting in it.
    cache = os.path.join(args.out, "rotations")
    os.makedirs(cache, exist_ok=True)
    cmd = [args.ltm, "render", ltm_file, "--env", env_path, "--brdf", spec,
           "--shading", "glossy", "--camera", ",".join(map(str, cam["eye"])),
           "--target", ",".join(map(str, cam["target"])), "--fov", str(cam["fov"]),
           "--size", f"{args.width}x{args.width}", "--supersample", "4",
           "--rotation-cache", cache, "-o", out, *extra]
    mt.run(cmd)


def ltm_relight_image(args, ltm_file, env_path, spec, out, extra=()):
    """The glossy image of an image-space file: its own camera's pixels."""
    cache = os.path.join(args.out, "rotations")
    os.makedirs(cache, exist_ok=True)
    mt.run([args.ltm, "relight", ltm_file, "--env", env_path, "--brdf", spec,
            "--shading", "glossy", "--rotation-cache", cache, "-o", out, *extra])


def bake_and_compress(args, toml, name):
    """`ltm bake` of the scene file `toml` compressed into
    `args.out/name.ltm` (the raw store removed)."""
    raw, ltm_file = os.path.join(args.out, "b.raw"), os.path.join(args.out, f"{name}.ltm")
    mt.run([args.ltm, "bake", toml, "-o", raw])
    mt.run([args.ltm, "compress", raw, "-o", ltm_file])
    os.remove(raw)
    return ltm_file


def bake_image_rows(args, mesh, cam, name):
    """Bakes and compresses the image rows of `mesh` seen from `cam`."""
    toml = os.path.join(args.out, f"{name}.toml")
    with open(toml, "w") as f:
        f.write(image_scene_toml(mesh, cam, args.width))
    return bake_and_compress(args, toml, name)


def compare(ours, ref, ref2, mask):
    err = mt.rel(ours, ref, mask)
    noise = mt.rel(ref2, ref, mask) / math.sqrt(2)
    return dict(rel_l2=err, mitsuba_noise=noise,
                rel_l2_noise_removed=math.sqrt(max(err ** 2 - noise ** 2, 0.0)))


def case(args, mi, ctx, material, alpha, extra=(), tag=""):
    """Renders one material on one mesh under one map from every camera."""
    mesh, ltm_file, env_path, env, masks, refs = ctx
    spec = ltm_spec(material, alpha)
    rows = []
    for c, cam in enumerate(args.cams):
        key = (material, alpha, c)
        if key not in refs:
            bsdf = mitsuba_bsdf(material, alpha)
            t0 = time.time()
            ref = mitsuba_render(mi, args, mesh, cam, env, bsdf, 1)
            ref2 = mitsuba_render(mi, args, mesh, cam, env, bsdf, 2)
            refs[key] = (ref, ref2, time.time() - t0)
        ref, ref2, mitsuba_s = refs[key]
        view = os.path.join(args.out, f"view{tag}.exr")
        t0 = time.time()
        if args.rows == "image":
            ltm_relight_image(args, ltm_file[c], env_path, spec, view, extra)
        else:
            ltm_render(args, ltm_file, env_path, cam, spec, view, extra)
        ltm_s = time.time() - t0
        ours = mt.read_exr(mi, view)
        row = dict(camera=c, spec=spec, extra=list(extra), ltm_s=ltm_s,
                   mitsuba_s=mitsuba_s, **compare(ours, ref, ref2, masks[c]))
        rows.append(row)
        if c == 0:
            peak = np.percentile(ref[masks[c]], 99.0)
            # ltm | Mitsuba | 4 x |difference|, on one scale.
            diff = 4 * np.abs(ours - ref) * masks[c][..., None]
            mc.save_png(os.path.join(args.out, f"{tag}{material}_{alpha}_cam{c}{'_'.join(extra)}.png"),
                        np.concatenate([ours, ref, diff], axis=1) / peak)
    return rows


def pct(x):
    return f"{100 * x:.2f} %"


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--ltm", default=os.path.join(ROOT, "target/release/ltm"))
    ap.add_argument("--meshes", default=",".join(MESHES))
    ap.add_argument("--maps", default=",".join(MAPS))
    ap.add_argument("--materials", default="lambert,conductor,coat")
    ap.add_argument("--alphas", default=",".join(map(str, ALPHAS)))
    ap.add_argument("--size", type=int, default=256, help="texture side S")
    ap.add_argument("--light-n", type=int, default=64,
                    help="face resolution of the piecewise-constant lighting")
    ap.add_argument("--env-height", type=int, default=1024)
    ap.add_argument("--width", type=int, default=128, help="view side in pixels")
    ap.add_argument("--cameras", type=int, default=2)
    ap.add_argument("--spp", type=int, default=1024, help="Mitsuba samples per pixel")
    ap.add_argument("--sampler", default="ldsampler", help="Mitsuba's sampler")
    ap.add_argument("--rows", choices=["texture", "image"], default="texture",
                    help="draw a texture-space bake with `ltm render`, or each "
                         "camera's image rows with `ltm relight`")
    ap.add_argument("--filters", action="store_true",
                    help="render each case once in Mitsuba and draw it four ways: image and "
                         "texture rows, each with --view-filter nearest and bilinear")
    ap.add_argument("--remeasure", action="store_true",
                    help="with --fixture: measure ltm's errors (both row layouts) against "
                         "the fixture's committed Mitsuba renders again, and reset the limits")
    ap.add_argument("--sweep", action="store_true")
    ap.add_argument("--extra", default="", help="more `ltm render` flags for every case")
    ap.add_argument("--variant", default="scalar_rgb")
    ap.add_argument("--out", default=None)
    ap.add_argument("--fixture", default=None, metavar="DIR",
                    help="write tools/tests/slow/glossy_mitsuba.rs's fixture into DIR and stop")
    args = ap.parse_args()

    import mitsuba as mi
    mi.set_variant(args.variant)
    args.out = args.out or tempfile.mkdtemp(prefix="ltm-glossy-")
    os.makedirs(args.out, exist_ok=True)
    args.cams = [dict(c, target=CENTER) for c in mt.DEFAULT_CAMERAS[:args.cameras]]
    alphas = [float(a) for a in args.alphas.split(",")]
    results = []
    print(f"Schlick against exact Fresnel at IOR {IOR}: {pct(fresnel_gap(IOR))}", flush=True)
    if args.fixture and args.remeasure:
        remeasure_fixture(args, mi)
        write_image_fixture(args, mi)
        return 0
    if args.fixture and args.rows == "image":
        write_image_fixture(args, mi)
        return 0
    if args.fixture:
        write_fixture(args, mi)
        return 0
    if args.filters:
        compare_filters(args, mi)
        return 0
    if args.sweep:
        args.meshes, args.maps, args.materials = "sphere", "studio", ""
    for mesh_name in args.meshes.split(","):
        mesh = mesh_file(mesh_name, args.out)
        toml = os.path.join(args.out, f"{mesh_name}.toml")
        with open(toml, "w") as f:
            f.write(scene_toml(mesh, args.cams[0], args.size))
        if args.rows == "image":
            ltm_file = [bake_image_rows(args, mesh, cam, f"{mesh_name}_cam{c}")
                        for c, cam in enumerate(args.cams)]
        else:
            ltm_file = bake_and_compress(args, toml, mesh_name)
        objects = [dict(path=mesh, scale=1.0, translation=[0.0, 0.0, 0.0])]
        masks = [mt.interior(mt.coverage_render(mi, objects, cam, args.width)) for cam in args.cams]
        for map_name in args.maps.split(","):
            env_path, env = lighting(mi, map_name, args.light_n, args.env_height, args.out)
            ctx = (mesh, ltm_file, env_path, env, masks, {})
            for material in filter(None, args.materials.split(",")):
                for alpha in ([None] if material == "lambert" else alphas):
                    rows = case(args, mi, ctx, material, alpha, args.extra.split(),
                                tag=f"{mesh_name}_{map_name}_")
                    for r in rows:
                        r.update(mesh=mesh_name, map=map_name, material=material, alpha=alpha)
                        print(json.dumps(r), flush=True)
                    results += rows
            if args.sweep:
                results += sweep(args, mi, ctx)
    with open(os.path.join(args.out, "summary.json"), "w") as f:
        json.dump(dict(mitsuba_version=mi.__version__, variant=args.variant, spp=args.spp,
                       sampler=args.sampler, rows=args.rows,
                       size=args.size, light_n=args.light_n, width=args.width,
                       fresnel_gap=fresnel_gap(IOR), results=results), f, indent=1)
    print(f"images and summary.json in {args.out}")
    return 0


def compare_filters(args, mi):
    """`--filters`: every case of the chosen meshes, maps, materials and
    alphas rendered once by Mitsuba (two seeds) from every camera, and
    drawn by ltm four ways against those renders: the camera's image rows
    (`ltm relight --brdf`) and the texture (`ltm render --brdf`), each with
    `--view-filter nearest` and `bilinear`. One JSON line per case and
    camera, and summary.json."""
    rows = []
    for mesh_name in args.meshes.split(","):
        mesh = mesh_file(mesh_name, args.out)
        toml = os.path.join(args.out, f"{mesh_name}.toml")
        with open(toml, "w") as f:
            f.write(scene_toml(mesh, args.cams[0], args.size))
        tex = bake_and_compress(args, toml, f"{mesh_name}_tex")
        images = [bake_image_rows(args, mesh, cam, f"{mesh_name}_cam{c}")
                  for c, cam in enumerate(args.cams)]
        objects = [dict(path=mesh, scale=1.0, translation=[0.0, 0.0, 0.0])]
        masks = [mt.interior(mt.coverage_render(mi, objects, cam, args.width)) for cam in args.cams]
        for map_name in args.maps.split(","):
            env_path, env = lighting(mi, map_name, args.light_n, args.env_height, args.out)
            for material in filter(None, args.materials.split(",")):
                for alpha in [float(a) for a in args.alphas.split(",")]:
                    spec, bsdf = ltm_spec(material, alpha), mitsuba_bsdf(material, alpha)
                    for c, cam in enumerate(args.cams):
                        refs = [mitsuba_render(mi, args, mesh, cam, env, bsdf, s) for s in (1, 2)]
                        row = dict(mesh=mesh_name, map=map_name, material=material,
                                   alpha=alpha, camera=c)
                        view = os.path.join(args.out, "view.exr")
                        for filt in ["nearest", "bilinear"]:
                            extra = ["--view-filter", filt]
                            ltm_relight_image(args, images[c], env_path, spec, view, extra)
                            ours = mt.read_exr(mi, view)
                            row[f"image_{filt}"] = compare(ours, *refs, masks[c])
                            ltm_render(args, tex, env_path, cam, spec, view, extra)
                            ours = mt.read_exr(mi, view)
                            row[f"texture_{filt}"] = compare(ours, *refs, masks[c])
                        print(json.dumps(row), flush=True)
                        rows.append(row)
    with open(os.path.join(args.out, "summary.json"), "w") as f:
        json.dump(dict(mitsuba_version=mi.__version__, spp=args.spp, width=args.width,
                       size=args.size, light_n=args.light_n, results=rows), f, indent=1)


FIXTURE_CASES = [("conductor", 0.2), ("conductor", 0.5), ("coat", 0.2), ("lambert", None)]


def write_fixture(args, mi):
    """What tools/tests/slow/glossy_mitsuba.rs reads: the sphere (a level-3
    icosphere OBJ and its scene), the sun map at n = 32 (`env.exr`),
    Mitsuba's render of the analytic sphere for each of FIXTURE_CASES from
    camera 0, the interior mask, and meta.json with Mitsuba's noise and a
    limit per case of 1.5 x ltm's error when the fixture was made
    (`--glossy-n 32`, texture 128)."""
    dest = os.path.abspath(args.fixture)
    os.makedirs(dest, exist_ok=True)
    n, width, cam = 32, args.width, args.cams[0]
    mesh = mesh_file("sphere", dest, level=3)
    with open(os.path.join(dest, "scene.toml"), "w") as f:
        f.write(scene_toml("sphere.obj", cam, 128))
    env_path, env = lighting(mi, "sun", n, 512, dest)
    os.replace(env_path, os.path.join(dest, "env.exr"))
    env_path = os.path.join(dest, "env.exr")
    sphere = {"type": "sphere", "center": CENTER, "radius": 0.5}
    cov_scene = {"type": "scene", "integrator": {"type": "direct", "hide_emitters": False},
                 "sensor": mt.sensor_dict(mi, cam, width, 16, sampler="stratified"),
                 "env": {"type": "constant", "radiance": {"type": "rgb", "value": 1.0}},
                 "s": dict(sphere, bsdf={"type": "diffuse", "reflectance": {
                     "type": "rgb", "value": 0.0}})}
    sky = np.array(mi.render(mi.load_dict(cov_scene), seed=7), dtype=np.float64)[..., 0]
    mask = mt.interior(np.clip(1.0 - sky, 0.0, 1.0))
    np.save(os.path.join(dest, "interior.npy"), mask.astype(np.float32))
    ltm_file = bake_and_compress(args, os.path.join(dest, "scene.toml"), "fixture")
    cases = []
    for material, alpha in FIXTURE_CASES:
        refs = []
        for seed in (1, 2):
            d = {"type": "scene", "integrator": {"type": "direct", "hide_emitters": True},
                 "sensor": mt.sensor_dict(mi, cam, width, args.spp, sampler=args.sampler),
                 "env": {"type": "envmap", "bitmap": mi.Bitmap(env.astype(np.float32))},
                 "s": dict(sphere, bsdf=mitsuba_bsdf(material, alpha))}
            refs.append(np.array(mi.render(mi.load_dict(d), seed=seed), dtype=np.float64)[..., :3])
        name = material if alpha is None else f"{material}_{alpha}"
        np.save(os.path.join(dest, f"mitsuba_{name}.npy"), refs[0].astype(np.float32))
        spec = ltm_spec(material, alpha)
        view = os.path.join(args.out, "fixture.exr")
        ltm_render(args, ltm_file, env_path, cam, spec, view, ["--glossy-n", str(n)])
        m = compare(mt.read_exr(mi, view), refs[0], refs[1], mask)
        limit = math.ceil(1.5 * m["rel_l2_noise_removed"] * 200) / 200
        cases.append(dict(name=name, spec=spec, mitsuba_noise=m["mitsuba_noise"],
                          measured=m["rel_l2_noise_removed"], limit=limit))
        print(json.dumps(cases[-1]), flush=True)
    meta = dict(camera=dict(eye=cam["eye"], target=cam["target"], fov=cam["fov"]),
                width=width, glossy_n=n, mitsuba_version=mi.__version__,
                variant=args.variant, sampler=args.sampler, mitsuba_spp=args.spp, cases=cases)
    with open(os.path.join(dest, "meta.json"), "w") as f:
        json.dump(meta, f, indent=2)


def remeasure_fixture(args, mi):
    """`--fixture DIR --remeasure`: ltm's texture-route error per case
    against the fixture's committed Mitsuba renders (its `measured` and
    `limit`), as `write_fixture` measured it, with no new Mitsuba render."""
    dest = os.path.abspath(args.fixture)
    with open(os.path.join(dest, "meta.json")) as f:
        meta = json.load(f)
    cam, width = meta["camera"], meta["width"]
    args.width = width
    ltm_file = bake_and_compress(args, os.path.join(dest, "scene.toml"), "fixture")
    mask = np.load(os.path.join(dest, "interior.npy")) > 0.5
    for case in meta["cases"]:
        ref = np.load(os.path.join(dest, f"mitsuba_{case['name']}.npy")).astype(np.float64)
        view = os.path.join(args.out, "fixture.exr")
        ltm_render(args, ltm_file, os.path.join(dest, "env.exr"), cam, case["spec"], view,
                   ["--glossy-n", str(meta["glossy_n"])])
        err = mt.rel(mt.read_exr(mi, view), ref, mask)
        case["measured"] = math.sqrt(max(err ** 2 - case["mitsuba_noise"] ** 2, 0.0))
        case["limit"] = math.ceil(1.5 * case["measured"] * 200) / 200
        print(json.dumps(case), flush=True)
    with open(os.path.join(dest, "meta.json"), "w") as f:
        json.dump(meta, f, indent=2)


def write_image_fixture(args, mi):
    """Adds the image-row route to an existing fixture (`--rows image
    --fixture DIR`): `image.toml`, the sphere's image rows from the
    fixture's camera at its width, and per case the error `ltm relight
    --brdf SPEC --shading glossy --glossy-n 32` has against the same
    Mitsuba renders (`image_measured`) and the test's limit (`image_limit`,
    1.5 x that, rounded up to 0.5 %)."""
    dest = os.path.abspath(args.fixture)
    with open(os.path.join(dest, "meta.json")) as f:
        meta = json.load(f)
    cam, width = meta["camera"], meta["width"]
    with open(os.path.join(dest, "image.toml"), "w") as f:
        f.write(image_scene_toml("sphere.obj", cam, width))
    ltm_file = bake_and_compress(args, os.path.join(dest, "image.toml"), "image")
    mask = np.load(os.path.join(dest, "interior.npy")) > 0.5
    for case in meta["cases"]:
        ref = np.load(os.path.join(dest, f"mitsuba_{case['name']}.npy")).astype(np.float64)
        view = os.path.join(args.out, "image.exr")
        ltm_relight_image(args, ltm_file, os.path.join(dest, "env.exr"), case["spec"], view,
                          ["--glossy-n", str(meta["glossy_n"])])
        err = mt.rel(mt.read_exr(mi, view), ref, mask)
        measured = math.sqrt(max(err ** 2 - case["mitsuba_noise"] ** 2, 0.0))
        case["image_measured"] = measured
        case["image_limit"] = math.ceil(1.5 * measured * 200) / 200
        print(json.dumps(case), flush=True)
    with open(os.path.join(dest, "meta.json"), "w") as f:
        json.dump(meta, f, indent=2)


SWEEP = [("--brdf-keep", ["0.03", "0.3", "1"]), ("--normals", ["16", "64"]),
         ("--glossy-terms", ["256", "2048"]), ("--glossy-n", ["32", "64", "128"])]


def sweep(args, mi, ctx):
    rows = []
    for alpha in (0.1, 0.2):
        for flag, values in SWEEP:
            for value in values:
                extra = [flag, value]
                for r in case(args, mi, ctx, "conductor", alpha, extra, tag="sweep_"):
                    r.update(mesh="sphere", map="studio", material="conductor", alpha=alpha)
                    print(json.dumps(r), flush=True)
                    rows.append(r)
    return rows


if __name__ == "__main__":
    sys.exit(main())
