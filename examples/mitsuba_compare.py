"""Render a view with Mitsuba 3, relight the same view with ltm, print the error.

The scene is tools/validate/diffuse.toml (Lambertian, flat-shaded: the
materials both renderers define alike). ltm bakes it, compresses the matrix
(1 % target error) and relights it under an environment map; Mitsuba renders
it with direct lighting under the same map. Needs `pip install ./python
mitsuba numpy`; run from anywhere:

    python examples/mitsuba_compare.py [--env assets/envmaps/courtyard.exr]
"""

import argparse
import pathlib
import tempfile
import tomllib

import mitsuba as mi
import numpy as np

import ltm

ROOT = pathlib.Path(__file__).resolve().parents[1]
SCENE = ROOT / "tools" / "validate" / "diffuse.toml"


def mitsuba_scene(desc, env, spp):
    """The scene description as a Mitsuba scene dict (two-sided diffuse)."""
    T, cam = mi.ScalarTransform4f, desc["camera"]

    def bsdf(name):
        albedo = desc["materials"][name]["albedo"]
        return {"type": "twosided", "material": {"type": "diffuse",
                "reflectance": {"type": "rgb", "value": albedo}}}

    def place(t, rot):  # ltm's rotation order: x, then y, then z
        return t.rotate([0, 0, 1], rot[2]).rotate([0, 1, 0], rot[1]).rotate([1, 0, 0], rot[0])

    d = {"type": "scene", "integrator": {"type": "direct", "hide_emitters": True},
         "sensor": {"type": "perspective", "fov": cam["fov"], "fov_axis": "y",
                    "to_world": T().look_at(origin=cam["eye"], target=cam["target"], up=[0, 1, 0]),
                    "film": {"type": "hdrfilm", "width": cam["width"], "height": cam["height"],
                             "rfilter": {"type": "box"}, "pixel_format": "rgb"},
                    "sampler": {"type": "independent", "sample_count": spp}},
         "env": {"type": "envmap", "bitmap": mi.Bitmap(env)}}
    for i, m in enumerate(desc["meshes"]):
        path = (SCENE.parent / m["path"]).resolve()
        to_world = place(T().translate(m["translation"]), m["rotation"]).scale([m["scale"]] * 3)
        d[f"mesh{i}"] = {"type": path.suffix[1:], "filename": str(path), "to_world": to_world,
                         "face_normals": True, "bsdf": bsdf(m["material"])}
    for i, q in enumerate(desc["quads"]):
        sx, sz = q["size"]
        to_world = T().translate(q["center"]).rotate([1, 0, 0], -90).scale([sx / 2, sz / 2, 1])
        d[f"quad{i}"] = {"type": "rectangle", "to_world": to_world, "bsdf": bsdf(q["material"])}
    return d


def error(a, b):
    return np.linalg.norm(a - b) / np.linalg.norm(b)


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--env", default=str(ROOT / "assets" / "envmaps" / "courtyard.exr"))
    p.add_argument("--size", type=int, default=64)
    p.add_argument("--face-res", type=int, default=16)
    p.add_argument("--spp", type=int, default=256, help="Mitsuba's samples per pixel")
    p.add_argument("--bake-spp", type=int, default=4, help="ltm's sub-samples per pixel")
    args = p.parse_args()
    mi.set_variant("scalar_rgb")
    desc = tomllib.loads(SCENE.read_text())
    desc["camera"].update(width=args.size, height=args.size)
    with tempfile.TemporaryDirectory() as tmp:
        raw, path = pathlib.Path(tmp) / "scene.raw", pathlib.Path(tmp) / "scene.ltm"
        ltm.bake(SCENE, raw, width=args.size, height=args.size, face_res=args.face_res,
                 texel_samples=1, spp=args.bake_spp)
        ltm.compress(raw, path, max_error=0.01)
        f = ltm.open(path)
        relit, _ = f.relighter().relight(args.env, terms="all")
        exact = ltm.reference(raw, args.env)
    env = np.maximum(ltm.read_exr(args.env), 0)
    rendered = mi.render(mi.load_dict(mitsuba_scene(desc, env, args.spp)), seed=1)
    theirs = np.array(rendered, dtype=np.float32)[..., :3]
    print(f"{args.size}² pixels, {f.dims['lights']} lights, {f.mode} file of {f.size} bytes "
          f"(matrix error {f.error:.4f}); Mitsuba {mi.__version__}, {args.spp} spp")
    print(f"relative L2 error against Mitsuba: ltm relit {error(relit, theirs):.4f}, "
          f"exact T·L {error(exact, theirs):.4f}; relit against exact {error(relit, exact):.4f}")


if __name__ == "__main__":
    main()
