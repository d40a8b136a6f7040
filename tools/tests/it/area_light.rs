//! `ltm relight --area-light`: near-field textured area lights from a bake
//! with a `[light_plane]` (raw store version 6, the `.ltm` NEAR chunk),
//! against the library computing the same rows with its own texture
//! conventions, added to a map's image, and the bad lights and files that
//! must exit non-zero with a message.

use ltm_codec::{Limits, LtmFile};
use ltm_relight::nearfield::{
    AreaLight, LightTexture, NearField, NearFieldMethod, NearFieldTerms, Placement,
};
use ltm_relight::{relative_l2, Image};
use std::path::Path;

fn ltm(args: &[&str]) -> (bool, String, String) {
    ltm_testkit::run(env!("CARGO_BIN_EXE_ltm"), args).into()
}

fn ok(args: &[&str]) -> String {
    let (ok, _, stderr) = ltm(args);
    assert!(ok, "ltm {args:?}: {stderr}");
    stderr
}

fn fails(args: &[&str], needle: &str) {
    let (ok, _, stderr) = ltm(args);
    assert!(!ok, "ltm {args:?} succeeded");
    assert!(stderr.contains(needle), "ltm {args:?}: {stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
}

/// A floor under a floating occluder seen from above, grey (one channel
/// and an albedo image), with a light plane 1.5 above the floor, lit side
/// down; `plane = false` leaves the plane out.
fn scene(plane: bool) -> String {
    let mut s = String::from(
        r#"
[camera]
eye = [0.0, 2.6, 2.2]
target = [0.0, 0.0, 0.0]
fov = 50.0
width = 24
height = 18

[lighting]
face_res = 4

[materials.grey]
type = "lambert"
albedo = [0.5, 0.4, 0.3]

[[quads]]
center = [0.0, 0.0, 0.0]
size = [4.0, 4.0]
material = "grey"

[[quads]]
center = [0.25, 0.6, 0.1]
size = [0.5, 0.4]
material = "grey"
"#,
    );
    if plane {
        s += "\n[light_plane]\norigin = [0.0, 1.5, 0.0]\nx_axis = [1.0, 0.0, 0.0]\ny_axis = [0.0, 0.0, 1.0]\norder = 16\n";
    }
    s
}

/// Bakes and compresses `scene(plane)` in `dir`: the `.ltm` path.
fn baked(dir: &Path, plane: bool) -> String {
    let name = if plane { "p" } else { "n" };
    let toml = dir.join(format!("{name}.toml"));
    std::fs::write(&toml, scene(plane)).unwrap();
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let raw = s(&dir.join(format!("{name}.raw")));
    let out = s(&dir.join(format!("{name}.ltm")));
    let stderr = ok(&["bake", &s(&toml), "-o", &raw]);
    if plane {
        assert!(stderr.contains("light plane's face: 16 × 16"), "{stderr}");
    }
    ok(&["compress", &raw, "-o", &out, "--mode", "2d"]);
    out
}

/// A 4×2 texture image (top row first), distinct in every texel and
/// channel.
fn texture_image() -> Image {
    let mut image = Image::new(4, 2);
    for (i, px) in image.data.iter_mut().enumerate() {
        let v = 1.0 + i as f32;
        *px = [v, 0.5 * v, 8.0 - v];
    }
    image
}

/// The light's texels (row 0 at the plane's −y edge) from the image as
/// the CLI documents it: its top row at +y.
fn texels(image: &Image, scale: f32) -> Vec<[f32; 3]> {
    image
        .data
        .chunks_exact(image.width)
        .rev()
        .flatten()
        .map(|t| t.map(|v| v * scale))
        .collect()
}

/// Every term of the wavelet propagation.
const ALL: NearFieldMethod = NearFieldMethod::Wavelet(NearFieldTerms::ALL);

fn library(file: &Path, light: AreaLight, method: NearFieldMethod) -> Image {
    let mut f = LtmFile::open(file).unwrap();
    let near = NearField::take(&mut f, &Limits::default()).unwrap();
    let data = near.render(&[light], method).unwrap();
    let (w, h) = (
        f.meta().dims.width() as usize,
        f.meta().dims.height() as usize,
    );
    Image {
        width: w,
        height: h,
        data,
    }
}

#[test]
fn area_lights_from_the_cli_match_the_library() {
    let dir = tempfile::tempdir().unwrap();
    let file = baked(dir.path(), true);
    let tex = dir.path().join("light.exr");
    let image = texture_image();
    image.write_exr(&tex).unwrap();
    let out = |n: &str| dir.path().join(n).to_str().unwrap().to_string();
    let all = [
        "--area-method",
        "wavelet",
        "--area-source-terms",
        "1",
        "--area-target-terms",
        "1",
    ];
    // The light at `angle` by `method` (extra flags), written to `o`.
    let light_by = |method: &[&str], angle: &str, o: &str| {
        let mut args = vec![
            "relight",
            &file,
            "--area-light",
            tex.to_str().unwrap(),
            "--area-center",
            "-0.1,0.2",
            "--area-size",
            "1,0.8",
            "--area-intensity",
            "2",
            "--area-angle",
            angle,
            "-o",
            o,
        ];
        args.extend(method);
        ok(&args);
        Image::read_exr(Path::new(o)).unwrap()
    };
    let light = |angle: &str, o: &str| light_by(&all, angle, o);
    let (ok_, stdout, _) = ltm(&["inspect", &file]);
    assert!(
        ok_ && stdout.contains("near field     16 x 16 face of side 4"),
        "{stdout}"
    );
    let cli = light("0", &out("a.exr"));
    let placement = Placement {
        center: [-0.1, 0.2],
        size: [1.0, 0.8],
        intensity: 1.0,
    };
    let texture = LightTexture::new(4, 2, texels(&image, 2.0)).unwrap();
    let light_of = |texture: &LightTexture| AreaLight {
        texture: texture.clone(),
        placement,
    };
    let want = library(Path::new(&file), light_of(&texture), ALL);
    let e = relative_l2(&cli, &want).unwrap();
    assert!(e < 1e-6, "CLI against the library: {e}");
    // The default method is exact; this texture divides the face's order,
    // so it is the same light as every wavelet term.
    let exact = light_by(&[], "0", &out("exact.exr"));
    let library_exact = library(Path::new(&file), light_of(&texture), NearFieldMethod::Exact);
    assert!(relative_l2(&exact, &library_exact).unwrap() < 1e-6);
    let e = relative_l2(&exact, &want).unwrap();
    assert!(e < 1e-5, "exact against every wavelet term: {e}");
    assert!(want.data.iter().any(|p| p[0] > 0.0), "the floor is lit");
    // Upside down is another picture: the orientation is seen.
    let flipped: Vec<[f32; 3]> = texels(&image, 2.0)
        .chunks_exact(4)
        .rev()
        .flatten()
        .copied()
        .collect();
    let flipped = LightTexture::new(4, 2, flipped).unwrap();
    let other = library(Path::new(&file), light_of(&flipped), ALL);
    assert!(relative_l2(&other, &want).unwrap() > 0.01);
    // A quarter turn counter-clockwise seen from the lit side (−Y): the
    // texel at column i, row j of the turned light is the old texel at
    // column j, row 1 − i of the 2-row texture; the sides swap.
    let turned: Vec<[f32; 3]> = (0..4)
        .flat_map(|j| (0..2).map(move |i| (i, j)))
        .map(|(i, j)| texture.texel(j, 1 - i))
        .collect();
    let turned = AreaLight {
        texture: LightTexture::new(2, 4, turned).unwrap(),
        placement: Placement {
            size: [0.8, 1.0],
            ..placement
        },
    };
    let e = relative_l2(
        &light("90", &out("b.exr")),
        &library(Path::new(&file), turned, ALL),
    )
    .unwrap();
    assert!(e < 1e-6, "turned: {e}");
    let e = relative_l2(&light("-270", &out("c.exr")), &light("90", &out("d.exr"))).unwrap();
    assert!(e == 0.0, "-270 and 90 degrees: {e}");
    // Any other angle resamples the texture: another picture, as bright.
    let (a, b) = (light("30", &out("e.exr")), light("0", &out("f.exr")));
    assert!(relative_l2(&a, &b).unwrap() > 1e-3);
    let total = |i: &Image| i.data.iter().map(|p| f64::from(p[1])).sum::<f64>();
    assert!(
        (total(&a) / total(&b) - 1.0).abs() < 0.1,
        "{} {}",
        total(&a),
        total(&b)
    );
}

#[test]
fn area_lights_add_to_the_map() {
    let dir = tempfile::tempdir().unwrap();
    let file = baked(dir.path(), true);
    let env = Path::new(env!("CARGO_MANIFEST_DIR")).join("../assets/envmaps/studio.exr");
    let env = env.to_str().unwrap();
    let out = |n: &str| dir.path().join(n).to_str().unwrap().to_string();
    let area = [
        "--area-light",
        "uniform",
        "--area-size",
        "0.6,0.6",
        "--area-intensity",
        "3",
    ];
    let mut both = vec!["relight", &file, "--env", env, "--terms", "all", "-o"];
    let both_path = out("both.exr");
    both.push(&both_path);
    both.extend(area);
    let stderr = ok(&both);
    assert!(
        stderr.contains("1 area light(s): 432 rows shaded"),
        "{stderr}"
    );
    ok(&[
        "relight",
        &file,
        "--env",
        env,
        "--terms",
        "all",
        "-o",
        &out("map.exr"),
    ]);
    let mut alone = vec!["relight", &file, "-o"];
    let alone_path = out("area.exr");
    alone.push(&alone_path);
    alone.extend(area);
    let stderr = ok(&alone);
    assert!(stderr.contains("the area lights alone"), "{stderr}");
    let read = |p: &str| Image::read_exr(Path::new(p)).unwrap();
    let (b, m, a) = (read(&both_path), read(&out("map.exr")), read(&alone_path));
    for ((x, y), z) in b.data.iter().zip(&m.data).zip(&a.data) {
        for c in 0..3 {
            assert!(
                (x[c] - (y[c] + z[c])).abs() <= 1e-6 * x[c].abs().max(1e-3),
                "{x:?} {y:?} {z:?}"
            );
        }
    }
}

/// `ltm compress --near-error`: rows at 1 % (the default with
/// `--max-error 0.01`) make a file several times smaller whose image is
/// within that of the lossless file's; `--near-error 0` is lossless, the
/// same as the library's rows; bad targets are refused.
#[test]
fn near_field_rows_are_quantized_to_their_target() {
    let dir = tempfile::tempdir().unwrap();
    let lossy = baked(dir.path(), true);
    let s = |n: &str| dir.path().join(n).to_str().unwrap().to_string();
    let (raw, exact) = (s("p.raw"), s("exact.ltm"));
    let said = ok(&[
        "compress",
        &raw,
        "-o",
        &exact,
        "--mode",
        "2d",
        "--near-error",
        "0",
    ]);
    assert!(said.contains("stored losslessly"), "{said}");
    let coarse = s("coarse.ltm");
    let said = ok(&[
        "compress",
        &raw,
        "-o",
        &coarse,
        "--mode",
        "2d",
        "--near-error",
        "0.1",
    ]);
    assert!(
        said.contains("Haar coefficients kept at one step"),
        "{said}"
    );
    let size = |p: &str| std::fs::metadata(p).unwrap().len();
    assert!(size(&coarse) < size(&lossy) && 2 * size(&lossy) < size(&exact));
    let light = [
        "--area-light",
        "uniform",
        "--area-size",
        "0.5,0.4",
        "--area-center",
        "0.2,0.1",
    ];
    let image = |file: &str, name: &str| {
        let out = s(name);
        ok(&[&["relight", file][..], &light, &["-o", &out]].concat());
        Image::read_exr(Path::new(&out)).unwrap()
    };
    let reference = image(&exact, "exact.exr");
    for (file, target) in [(&lossy, 0.01), (&coarse, 0.1)] {
        let moved = relative_l2(&image(file, "q.exr"), &reference).unwrap();
        assert!(moved > 0.0 && moved < target, "{file}: {moved}");
    }
    for (bad, says) in [
        ("-0.1", "near-field error"),
        ("1", "near-field error"),
        ("NaN", "near-field error"),
    ] {
        let flag = format!("--near-error={bad}");
        fails(&["compress", &raw, "-o", &s("bad.ltm"), &flag], says);
    }
    fails(
        &[
            "compress",
            &raw,
            "-o",
            &s("bad.ltm"),
            "--mode",
            "pca",
            "--near-error",
            "0.01",
        ],
        "--near-error applies to the wavelet modes",
    );
}

#[test]
fn bad_area_lights_and_files_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let file = baked(dir.path(), true);
    let plain = baked(dir.path(), false);
    let out = dir.path().join("o.exr");
    let o = out.to_str().unwrap();
    let u = "uniform";
    fails(
        &["relight", &plain, "--area-light", u, "-o", o],
        "no near-field rows",
    );
    fails(
        &[
            "relight",
            &file,
            "--area-light",
            u,
            "--area-angle",
            "nan",
            "-o",
            o,
        ],
        "not finite",
    );
    fails(
        &[
            "relight",
            &file,
            "--area-light",
            u,
            "--area-light",
            u,
            "--area-light",
            u,
            "--area-size",
            "1,1",
            "--area-size",
            "2,2",
            "-o",
            o,
        ],
        "2 --area-size given for 3 --area-light",
    );
    fails(
        &[
            "relight",
            &file,
            "--area-light",
            u,
            "--area-size",
            "0,1",
            "-o",
            o,
        ],
        "light width",
    );
    fails(
        &[
            "relight",
            &file,
            "--area-light",
            u,
            "--area-center",
            "nan,0",
            "-o",
            o,
        ],
        "not finite",
    );
    fails(
        &[
            "relight",
            &file,
            "--area-light",
            u,
            "--area-source-terms",
            "0",
            "-o",
            o,
        ],
        "(0, 1]",
    );
    fails(
        &[
            "relight",
            &file,
            "--area-light",
            u,
            "--area-target-terms",
            "0.5",
            "-o",
            o,
        ],
        "apply to --area-method wavelet",
    );
    fails(
        &["relight", &file, "--area-light", "light.jpg", "-o", o],
        ".exr or .png",
    );
    fails(&["relight", &file, "-o", o], "--env");
    // A bake with a light plane cannot be sharded (the parts would drop it).
    let toml = dir.path().join("p.toml");
    let part = dir.path().join("part.raw");
    fails(
        &[
            "bake",
            toml.to_str().unwrap(),
            "--shard",
            "0/2",
            "-o",
            part.to_str().unwrap(),
        ],
        "near-field",
    );
    // Lights behind every row (a plane below the floor, lit side down)
    // give a defined, black image.
    let below = scene(true).replace("origin = [0.0, 1.5, 0.0]", "origin = [0.0, -1.0, 0.0]");
    let below_toml = dir.path().join("below.toml");
    std::fs::write(&below_toml, below).unwrap();
    let s = |p: &Path| p.to_str().unwrap().to_string();
    ok(&[
        "bake",
        &s(&below_toml),
        "-o",
        &s(&dir.path().join("below.raw")),
    ]);
    let below_ltm = s(&dir.path().join("below.ltm"));
    ok(&[
        "compress",
        &s(&dir.path().join("below.raw")),
        "-o",
        &below_ltm,
        "--mode",
        "2d",
    ]);
    ok(&["relight", &below_ltm, "--area-light", u, "-o", o]);
    let image = Image::read_exr(&out).unwrap();
    assert!(image.data.iter().flatten().all(|v| *v == 0.0));
}

/// `ltm render --area-light` on a texture-space file adds the area light
/// to the relit texture exactly as `ltm relight --area-light` relights the
/// file's texels, and the drawn views show it.
#[test]
fn area_lights_in_ltm_render_match_ltm_relight() {
    let dir = tempfile::tempdir().unwrap();
    let out = |n: &str| dir.path().join(n).to_str().unwrap().to_string();
    std::fs::write(dir.path().join("blob.obj"), ltm_testkit::blob_obj(4)).unwrap();
    let texture_scene =
        ltm_testkit::scene_toml("blob.obj", 8, 8, 4) + ltm_testkit::TEXTURE_SPHERE_16;
    let bake = |name: &str, scene: String| -> String {
        let toml = out(&format!("{name}.toml"));
        std::fs::write(&toml, scene).unwrap();
        let (raw, file) = (out(&format!("{name}.raw")), out(&format!("{name}.ltm")));
        ok(&["bake", &toml, "-o", &raw]);
        ok(&["compress", &raw, "-o", &file, "--mode", "2d"]);
        file
    };
    let plane = "\n[light_plane]\norigin = [0.0, 2.5, 0.0]\nx_axis = [1.0, 0.0, 0.0]\ny_axis = [0.0, 0.0, 1.0]\norder = 8\n";
    let file = bake("t", texture_scene.clone() + plane);
    let env = Path::new(env!("CARGO_MANIFEST_DIR")).join("../assets/envmaps/studio.exr");
    let env = env.to_str().unwrap().to_string();
    let light = [
        "--area-light",
        "uniform",
        "--area-size",
        "1.5,1",
        "--area-center",
        "0.3,0",
        "--area-intensity",
        "5",
    ];
    let relit = out("relit.exr");
    let mut args = vec![
        "relight", &file, "--env", &env, "--terms", "all", "-o", &relit,
    ];
    args.extend(light);
    ok(&args);
    let view = [
        "--camera", "0,1.5,3", "--target", "0,0.6,0", "--size", "48", "--terms", "all",
    ];
    let render = |file: &str, with_light: bool, texture: &str, image: &str| {
        let mut args = vec!["render", file, "--env", &env];
        args.extend(view);
        args.extend(["--texture", texture, "-o", image]);
        if with_light {
            args.extend(light);
        }
        ltm(&args)
    };
    let (done, _, stderr) = render(&file, true, &out("lit.exr"), &out("lit-view.exr"));
    assert!(done && stderr.contains("1 area light(s) added"), "{stderr}");
    let (done, _, stderr) = render(&file, false, &out("dark.exr"), &out("dark-view.exr"));
    assert!(done, "{stderr}");
    let read = |n: &str| Image::read_exr(Path::new(&out(n))).unwrap();
    let e = relative_l2(&read("lit.exr"), &read("relit.exr")).unwrap();
    assert!(e < 1e-6, "render's texture against relight's: {e}");
    assert!(relative_l2(&read("dark.exr"), &read("lit.exr")).unwrap() > 0.01);
    assert!(relative_l2(&read("dark-view.exr"), &read("lit-view.exr")).unwrap() > 0.01);
    // A file without near-field rows is refused with a message.
    let plain = bake("plain", texture_scene);
    let (done, _, stderr) = render(&plain, true, &out("x.exr"), &out("y.exr"));
    assert!(!done && stderr.contains("[light_plane]"), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
}
