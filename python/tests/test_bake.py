import subprocess

import numpy as np
import pytest

import ltm
from conftest import ENVMAP, ltm_binary, relative_l2

# The test scene of tools/testkit (scene.rs): a camera over a ground quad
# and one Lambertian mesh.
SCENE = """
[camera]
eye = [0.0, 1.0, 3.0]
target = [0.0, 0.5, 0.0]
fov = 30.0
width = 16
height = 12

[lighting]
face_res = 2
texel_samples = 1

[materials.clay]
type = "lambert"
albedo = [0.7, 0.6, 0.5]

[[meshes]]
path = "MESH"
material = "clay"
translation = [0.0, 0.6, 0.0]

[[quads]]
center = [0.0, 0.0, 0.0]
size = [4.0, 4.0]
material = "clay"
"""

TEXTURE = '\n[texture]\nmesh = 0\nsize = 16\nparameterization = "sphere"\nspp = 1\n'


# A closed octahedron of radius 0.5.
OCTAHEDRON = """v 0.5 0 0
v -0.5 0 0
v 0 0.5 0
v 0 -0.5 0
v 0 0 0.5
v 0 0 -0.5
f 1 3 5
f 3 2 5
f 2 4 5
f 4 1 5
f 3 1 6
f 2 3 6
f 4 2 6
f 1 4 6
"""


def scene(tmp_path, texture=False):
    (tmp_path / "octahedron.obj").write_text(OCTAHEDRON)
    path = tmp_path / "scene.toml"
    path.write_text(SCENE.replace("MESH", "octahedron.obj") + (TEXTURE if texture else ""))
    return path


def test_bake_compress_relight_against_reference(tmp_path, sky):
    seen = []
    report = ltm.bake(scene(tmp_path), tmp_path / "s.raw", width=8, height=8,
                      progress=lambda *step: seen.append(step))
    assert report["dims"]["width"] == 8 and report["dims"]["lights"] == 24
    assert report["rows_baked"] == 64
    assert seen[-1] == ("bake", 64, 64)
    exact = ltm.reference(tmp_path / "s.raw", sky, rotation=(40, 0, 0))
    f = ltm.open(ltm.compress(tmp_path / "s.raw", max_error=0.01))
    assert f.meta["has_albedo"]
    image, _ = f.relighter().relight(sky, terms="all", rotation=(40, 0, 0))
    assert relative_l2(image, exact) <= 0.01


PLANE = '\n[light_plane]\norigin = [0.0, 1.5, 0.0]\nx_axis = [1.0, 0.0, 0.0]\ny_axis = [0.0, 0.0, 1.0]\norder = 8\n'


def test_near_field_rows_at_a_target_are_the_cli(tmp_path):
    path = scene(tmp_path)
    path.write_text(path.read_text() + PLANE)
    ltm.bake(path, tmp_path / "p.raw", width=8, height=8)
    sizes = {}
    for near in (0.0, 0.05):
        out = tmp_path / f"near-{near}.ltm"
        stats = ltm.compress(tmp_path / "p.raw", out, near_error=near)
        assert 0.0 <= stats["near_field_error"] <= near and stats["near_field_bytes"] > 0
        cli = tmp_path / f"cli-{near}.ltm"
        subprocess.run([ltm_binary(), "compress", str(tmp_path / "p.raw"), "-o", str(cli),
                        "--near-error", str(near)], check=True, capture_output=True)
        assert out.read_bytes() == cli.read_bytes()
        sizes[near] = stats["near_field_bytes"]
    assert sizes[0.05] < sizes[0.0]
    with pytest.raises(ValueError, match="near-field error"):
        ltm.compress(tmp_path / "p.raw", near_error=1.5)
    with pytest.raises(ValueError, match="near_error applies to the wavelet modes"):
        ltm.compress(tmp_path / "p.raw", mode="pca", near_error=0.01)


def test_bake_errors(tmp_path):
    with pytest.raises(FileNotFoundError):
        ltm.bake(tmp_path / "none.toml", tmp_path / "x.raw")
    with pytest.raises(ValueError, match="face-res = 3"):
        ltm.bake(scene(tmp_path), tmp_path / "x.raw", face_res=3)


def test_render_of_a_texture_file_is_the_cli(tmp_path):
    ltm.bake(scene(tmp_path, texture=True), tmp_path / "t.raw")
    path = tmp_path / "t.ltm"
    ltm.compress(tmp_path / "t.raw", path, max_error=0.02)
    r = ltm.open(path).relighter()
    view, _ = r.render(ENVMAP, camera=(0, 1, 3), target=(0, 0.5, 0), size=(24, 16))
    assert view.shape == (16, 24, 3) and np.isfinite(view).all() and view.max() > 0
    out = tmp_path / "view.exr"
    subprocess.run([ltm_binary(), "render", str(path), "--env", str(ENVMAP), "--camera",
                    "0,1,3", "--target", "0,0.5,0", "--size", "24x16", "-o", str(out)],
                   check=True, capture_output=True)
    assert np.array_equal(view, ltm.read_exr(out))
    with pytest.raises(ValueError, match="supersample"):
        r.render(ENVMAP, camera=(0, 1, 3), target=(0, 0.5, 0), supersample=9)
