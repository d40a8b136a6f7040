//! Geometry relighting through the `ltm` binary: a texture-space bake of a
//! small closed mesh relit and drawn from a camera, and the bad input of
//! issue 13, each a clear message and a non-zero exit (never a panic).

use std::fmt::Write as _;
use std::path::Path;

fn ltm(args: &[&str]) -> (bool, String) {
    let run = ltm_testkit::run(env!("CARGO_BIN_EXE_ltm"), args);
    assert!(!run.stderr.contains("panicked"), "{args:?}: {}", run.stderr);
    (run.ok, run.stderr)
}

fn fails(args: &[&str], expect: &[&str]) {
    let (ok, stderr) = ltm(args);
    assert!(!ok, "{args:?} succeeded");
    for e in expect {
        assert!(stderr.contains(e), "{args:?}: {stderr}");
    }
}

/// An octahedron subdivided `level` times and pushed onto a sphere of
/// radius 0.5 (closed, genus 0), with extra OBJ lines appended.
fn sphere_obj(level: usize, extra: &str) -> String {
    let mut v: Vec<[f64; 3]> = vec![
        [1.0, 0.0, 0.0],
        [-1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, -1.0, 0.0],
        [0.0, 0.0, 1.0],
        [0.0, 0.0, -1.0],
    ];
    let mut f: Vec<[usize; 3]> = vec![
        [0, 2, 4],
        [2, 1, 4],
        [1, 3, 4],
        [3, 0, 4],
        [2, 0, 5],
        [1, 2, 5],
        [3, 1, 5],
        [0, 3, 5],
    ];
    for _ in 0..level {
        let mut mid = std::collections::HashMap::new();
        let mut nf = Vec::new();
        for t in &f {
            let m: Vec<usize> = (0..3)
                .map(|k| {
                    let key = (t[k].min(t[(k + 1) % 3]), t[k].max(t[(k + 1) % 3]));
                    *mid.entry(key).or_insert_with(|| {
                        v.push([0, 1, 2].map(|i| (v[key.0][i] + v[key.1][i]) / 2.0));
                        v.len() - 1
                    })
                })
                .collect();
            nf.extend([
                [t[0], m[0], m[2]],
                [t[1], m[1], m[0]],
                [t[2], m[2], m[1]],
                [m[0], m[1], m[2]],
            ]);
        }
        f = nf;
    }
    let mut s = String::new();
    for p in &v {
        let l = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt() * 2.0;
        writeln!(s, "v {} {} {}", p[0] / l, p[1] / l, p[2] / l).unwrap();
    }
    for t in &f {
        writeln!(s, "f {} {} {}", t[0] + 1, t[1] + 1, t[2] + 1).unwrap();
    }
    s + extra
}

const TEXTURE: &str = ltm_testkit::TEXTURE_SPHERE_16;

fn write_scene(dir: &Path, name: &str, mesh: &str, texture: &str) -> String {
    let path = dir.join(name);
    std::fs::write(&path, ltm_testkit::scene_toml(mesh, 8, 8, 2) + texture).unwrap();
    path.to_str().unwrap().to_string()
}

fn args(v: &[String]) -> Vec<&str> {
    v.iter().map(String::as_str).collect()
}

fn env_map() -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../assets/envmaps/studio.exr")
        .to_str()
        .unwrap()
        .to_string()
}

#[test]
fn texture_bakes_render_and_bad_input_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let p = |n: &str| d.join(n).to_str().unwrap().to_string();
    std::fs::write(d.join("sphere.obj"), sphere_obj(2, "")).unwrap();
    let env = env_map();

    // A texture-space and an image-space file of the same scene.
    let tex = write_scene(d, "tex.toml", "sphere.obj", TEXTURE);
    let img = write_scene(d, "img.toml", "sphere.obj", "");
    for (scene, name) in [(&tex, "tex"), (&img, "img")] {
        let raw = p(&format!("{name}.raw"));
        assert!(ltm(&["bake", scene, "-o", &raw]).0);
        assert!(ltm(&["compress", &raw, "-o", &p(&format!("{name}.ltm"))]).0);
    }
    // `inspect` names a texture's rows texels, an image's pixels.
    let inspect =
        |name: &str| ltm_testkit::run_ok(env!("CARGO_BIN_EXE_ltm"), &["inspect", &p(name)]);
    let tex_info = inspect("tex.ltm");
    assert!(
        tex_info.contains("texture ") && tex_info.contains(" texels,"),
        "{tex_info}"
    );
    assert!(!tex_info.contains("pixel"), "{tex_info}");
    let img_info = inspect("img.ltm");
    assert!(
        img_info.contains("image ") && img_info.contains(" pixels,"),
        "{img_info}"
    );
    let view = p("view.exr");
    let render = |file: &str, eye: &str| {
        vec![
            "render".to_string(),
            file.to_string(),
            "--env".into(),
            env.clone(),
            "--camera".into(),
            eye.to_string(),
            "--target".into(),
            "0,0.6,0".into(),
            "--size".into(),
            "24x16".into(),
            "-o".into(),
            view.clone(),
        ]
    };
    let (ok, stderr) = ltm(&args(&render(&p("tex.ltm"), "0,1,3")));
    assert!(ok, "{stderr}");
    assert!(Path::new(&view).exists());
    std::fs::remove_file(&view).unwrap();

    // An image-space file where a texture-space one is needed.
    fails(
        &args(&render(&p("img.ltm"), "0,1,3")),
        &["image-space file"],
    );
    // A raw store instead of a compressed file.
    fails(
        &args(&render(&p("tex.raw"), "0,1,3")),
        &["not an .ltm file"],
    );
    // A NaN camera, and a camera inside the mesh.
    fails(&args(&render(&p("tex.ltm"), "nan,1,3")), &["not finite"]);
    fails(
        &args(&render(&p("tex.ltm"), "0.05,0.6,0.02")),
        &["inside the mesh"],
    );
    // A camera on its target.
    fails(&args(&render(&p("tex.ltm"), "0,0.6,0")), &["coincide"]);
    // A camera straight above its target, with the default up: the message
    // names the eye and the target and says which flag to change.
    fails(
        &args(&render(&p("tex.ltm"), "0,5,0")),
        &["parallel", "eye", "target", "--up"],
    );
    assert!(!Path::new(&view).exists());
    // A far camera is a camera: its view direction is defined.
    for far in ["0,1,1e6", "0,1e200,3e200"] {
        let (ok, stderr) = ltm(&args(&render(&p("tex.ltm"), far)));
        assert!(ok, "{far}: {stderr}");
        std::fs::remove_file(&view).unwrap();
    }
    // A pca texture file renders too.
    let pca = p("tex-pca.ltm");
    let (ok, stderr) = ltm(&[
        "compress",
        &p("tex.raw"),
        "--mode",
        "pca",
        "--rank",
        "8",
        "-o",
        &pca,
    ]);
    assert!(ok, "{stderr}");
    let (ok, stderr) = ltm(&args(&render(&pca, "0,1,3")));
    assert!(ok, "{stderr}");
    assert!(Path::new(&view).exists());
    std::fs::remove_file(&view).unwrap();

    // A texture relit and compared with a reference of the image space:
    // the sizes differ.
    let reference = p("ref.exr");
    assert!(ltm(&["reference", &p("img.raw"), "--env", &env, "-o", &reference]).0);
    fails(
        &[
            "relight",
            &p("tex.ltm"),
            "--env",
            &env,
            "-o",
            &p("t.exr"),
            "--reference",
            &reference,
        ],
        &["16×16", "8×8"],
    );
}

#[test]
fn bad_texture_scenes_are_refused_by_bake() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let out = d.join("o.raw");
    let out = out.to_str().unwrap();
    let sphere = sphere_obj(1, "");
    let n = sphere.lines().filter(|l| l.starts_with("v ")).count();
    let meshes: &[(&str, String)] = &[
        ("sphere.obj", sphere.clone()),
        // A triangle that repeats a vertex.
        ("repeat.obj", sphere_obj(1, "f 1 1 2\n")),
        // Every triangle of zero area.
        (
            "flat.obj",
            "v 0 0 0\nv 1 0 0\nv 2 0 0\nv 3 0 0\nf 1 2 3\nf 1 3 4\nf 1 4 2\nf 2 4 3\n".into(),
        ),
        // A fin on one edge: three triangles meet there.
        (
            "fin.obj",
            sphere_obj(1, &format!("v 2 2 2\nf 1 3 {}\n", n + 1)),
        ),
    ];
    for (name, text) in meshes {
        std::fs::write(d.join(name), text).unwrap();
    }
    let count = std::cell::Cell::new(0);
    let scene = |mesh: &str, texture: &str| {
        count.set(count.get() + 1);
        write_scene(d, &format!("s{}.toml", count.get()), mesh, texture)
    };
    let cases: Vec<(String, Vec<&str>)> = vec![
        (
            scene("repeat.obj", TEXTURE),
            vec!["repeat.obj", "repeats vertex"],
        ),
        (
            scene("flat.obj", TEXTURE),
            vec!["flat.obj", "degenerate (zero area)"],
        ),
        (scene("fin.obj", TEXTURE), vec!["fin.obj", "edges"]),
        (
            scene("sphere.obj", &TEXTURE.replace("mesh = 0", "mesh = 2")),
            vec!["texture.mesh = 2", "0..1"],
        ),
        (
            scene("sphere.obj", &TEXTURE.replace("size = 16", "size = 0")),
            vec!["texture.size = 0", "1..=4096"],
        ),
        (
            scene("sphere.obj", &TEXTURE.replace("size = 16", "size = 4097")),
            vec!["texture.size = 4097", "1..=4096"],
        ),
        (
            scene("sphere.obj", &TEXTURE.replace("\"sphere\"", "\"uv\"")),
            vec!["no texture coordinates"],
        ),
    ];
    for (scene, expect) in cases {
        fails(&["bake", &scene, "-o", out], &expect);
        assert!(!Path::new(out).exists());
    }
}

/// Width and height from a PNG file's IHDR chunk.
fn png_size(path: &Path) -> (u32, u32) {
    let bytes = std::fs::read(path).unwrap();
    assert!(bytes.starts_with(b"\x89PNG\r\n\x1a\n") && &bytes[12..16] == b"IHDR");
    let be = |i: usize| u32::from_be_bytes(bytes[i..i + 4].try_into().unwrap());
    (be(16), be(20))
}

/// `ltm report` on a texture-space matrix adds the geometry section: the
/// relit texture (S × S) and two views of the mesh, with the relight and
/// relight-plus-view times; an image-space report has none
/// (`report_quick_writes_every_section` in cli.rs).
#[test]
fn report_on_a_texture_space_matrix_shows_the_texture_and_two_views() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("sphere.obj"), sphere_obj(2, "")).unwrap();
    let scene = write_scene(d, "tex.toml", "sphere.obj", TEXTURE);
    let raw = d.join("tex.raw");
    assert!(ltm(&["bake", &scene, "-o", raw.to_str().unwrap()]).0);
    let out = d.join("report");
    let (ok, stderr) = ltm(&[
        "report",
        "--quick",
        "--raw",
        raw.to_str().unwrap(),
        "--env",
        &env_map(),
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(ok, "{stderr}");
    let index = std::fs::read_to_string(out.join("index.md")).unwrap();
    assert!(index.contains("## 6. Geometry relighting"), "{index}");
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("results.json")).unwrap()).unwrap();
    let t = &r["texture"];
    assert_eq!(t["texture_side"], 16);
    assert!(t["triangles"].as_u64().unwrap() > 0);
    let (alone, with_view) = (
        t["relight_ms"].as_f64().unwrap(),
        t["relight_view_ms"].as_f64().unwrap(),
    );
    assert!(alone > 0.0 && with_view > 0.0 && alone.is_finite() && with_view.is_finite());
    let images: Vec<&str> = t["images"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_str().unwrap())
        .collect();
    assert_eq!(images, ["texture.png", "view-front.png", "view-back.png"]);
    assert_eq!(png_size(&out.join("texture.png")), (16, 16));
    for view in &images[1..] {
        assert_eq!(png_size(&out.join(view)), (512, 512), "{view}");
        assert!(
            index.contains(&format!("]({view})")),
            "index.md does not show {view}"
        );
    }
    assert!(out.join(t["file"].as_str().unwrap()).is_file());
}

/// `ltm render` names its views one way for -o and --png: the names given
/// for one view, numbered NAME-000, NAME-001, ... for several (never a
/// mix); the PNGs of an orbit share one exposure, which is printed.
#[test]
fn render_names_every_view_alike_for_exr_and_png() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let p = |n: &str| d.join(n).to_str().unwrap().to_string();
    std::fs::write(d.join("sphere.obj"), sphere_obj(2, "")).unwrap();
    let scene = write_scene(d, "tex.toml", "sphere.obj", TEXTURE);
    assert!(ltm(&["bake", &scene, "-o", &p("tex.raw")]).0);
    assert!(ltm(&["compress", &p("tex.raw"), "-o", &p("tex.ltm")]).0);
    let env = env_map();
    let render = |views: &str, out: &str| {
        let (exr, png) = (p(&format!("{out}.exr")), p(&format!("{out}.png")));
        let (tex, views) = (p("tex.ltm"), views.to_string());
        let a = [
            "render", &tex, "--env", &env, "--camera", "0,1,3", "--target", "0,0.6,0", "--size",
            "24x16", "--views", &views, "-o", &exr, "--png", &png,
        ];
        let (ok, stderr) = ltm(&a);
        assert!(ok, "{stderr}");
        stderr
    };
    let stderr = render("3", "orbit");
    let mut names: Vec<String> = std::fs::read_dir(d)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with("orbit"))
        .collect();
    names.sort();
    let want = [
        "orbit-000.exr",
        "orbit-000.png",
        "orbit-001.exr",
        "orbit-001.png",
        "orbit-002.exr",
        "orbit-002.png",
    ];
    assert_eq!(names, want);
    assert!(
        stderr.contains("orbit-000.png ... ") && stderr.contains("orbit-002.png"),
        "{stderr}"
    );
    assert!(stderr.contains("EV "), "{stderr}");
    render("1", "one");
    assert!(d.join("one.exr").is_file() && d.join("one.png").is_file());
    assert!(!d.join("one-000.png").exists());
}

/// `ltm bake SCENE --texture MESH --texture-size S` bakes a texture from a
/// scene file without a [texture] section (the same matrix size and rows
/// as the section would), and bad texture flags are refused with the flag
/// and what to give instead.
#[test]
fn texture_bakes_from_flags_without_editing_the_scene() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let p = |n: &str| d.join(n).to_str().unwrap().to_string();
    std::fs::write(d.join("sphere.obj"), sphere_obj(1, "")).unwrap();
    let img = write_scene(d, "img.toml", "sphere.obj", "");
    let flags = ["--texture", "0", "--texture-size", "16"];
    let mut args = vec!["bake", img.as_str(), "-o"];
    let out = p("flags.raw");
    args.push(&out);
    args.extend(flags);
    args.extend(["--parameterization", "sphere"]);
    let (ok, stderr) = ltm(&args);
    assert!(ok, "{stderr}");
    assert!(stderr.contains("texture 16² (sphere)"), "{stderr}");
    assert!(stderr.contains("baking 16 × 16 texels"), "{stderr}");
    // The file is a texture-space store: relit, it is a 16×16 texture.
    let (ok, stderr) = ltm(&["compress", &out, "-o", &p("flags.ltm")]);
    assert!(ok, "{stderr}");
    let relit = p("t.exr");
    let (ok, stderr) = ltm(&[
        "relight",
        &p("flags.ltm"),
        "--env",
        &env_map(),
        "-o",
        &relit,
    ]);
    assert!(ok, "{stderr}");
    let (ok, stderr) = ltm(&[
        "render",
        &p("flags.ltm"),
        "--env",
        &env_map(),
        "--camera",
        "0,1,3",
        "--target",
        "0,0.5,0",
        "--size",
        "8x8",
        "-o",
        &p("v.exr"),
    ]);
    assert!(ok, "{stderr}");
    let bad = p("bad.raw");
    for (extra, expect) in [
        (
            &["--texture", "0"][..],
            &["--texture", "--texture-size S"][..],
        ),
        (
            &["--texture-size", "16"],
            &["--texture-size", "--texture MESH"],
        ),
        (
            &["--parameterization", "uv"],
            &["--parameterization", "--texture MESH"],
        ),
        (
            &["--texture", "3", "--texture-size", "16"],
            &["texture.mesh = 3"],
        ),
        (
            &["--texture", "first", "--texture-size", "16"],
            &["'first'", "all"],
        ),
        (
            &["--texture", "0", "--texture-size", "0"],
            &["texture.size = 0", "1..=4096"],
        ),
    ] {
        let mut args = vec!["bake", img.as_str(), "-o", bad.as_str()];
        args.extend_from_slice(extra);
        fails(&args, expect);
        assert!(!Path::new(&bad).exists());
    }
}

/// A sphere alone (no ground: nothing shadows it), Lambertian, with a 32²
/// texture.
const LONE_SPHERE: &str = r#"
[camera]
eye = [0.0, 1.0, 3.0]
target = [0.0, 0.6, 0.0]
fov = 30.0
width = 8
height = 8

[lighting]
face_res = 8
texel_samples = 16

[materials.clay]
type = "lambert"
albedo = [0.7, 0.6, 0.5]

[[meshes]]
path = "sphere.obj"
material = "clay"
translation = [0.0, 0.6, 0.0]

[texture]
mesh = 0
size = 32
parameterization = "sphere"
spp = 1
"#;

#[test]
fn render_brdf_shades_by_rotation_and_agrees_with_the_transport() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let p = |n: &str| d.join(n).to_str().unwrap().to_string();
    std::fs::write(d.join("sphere.obj"), sphere_obj(3, "")).unwrap();
    std::fs::write(d.join("lone.toml"), LONE_SPHERE).unwrap();
    assert!(ltm(&["bake", &p("lone.toml"), "-o", &p("lone.raw")]).0);
    let (ok, stderr) = ltm(&[
        "compress",
        &p("lone.raw"),
        "--max-error",
        "0.002",
        "-o",
        &p("lone.ltm"),
    ]);
    assert!(ok, "{stderr}");
    // A smooth map, different along every axis (a sun or a small lamp
    // would test the rotation's resolution, not its conventions).
    let tilted = ltm_relight::Image::from_data(
        128,
        64,
        (0..128 * 64)
            .map(|i| {
                let (u, v) = ((i % 128) as f64 + 0.5, (i / 128) as f64 + 0.5);
                let d = ltm_codec::cubemap::latlong_direction(u / 128.0, v / 64.0);
                let rgb = [
                    1.0 + 3.0 * d.y.max(0.0) + 0.8 * d.x,
                    1.0 + 2.0 * d.y.max(0.0) + 0.5 * d.z,
                    0.5 + (-d.y).max(0.0),
                ];
                rgb.map(|c| c as f32)
            })
            .collect(),
    )
    .unwrap();
    let env = p("tilted.exr");
    tilted.write_exr(Path::new(&env)).unwrap();
    let render = |out: &str, env: &str, extra: &[&str]| {
        let mut args = vec![
            "render", "LTM", "--env", env, "--camera", "0.4,1,3", "--target", "0,0.6,0", "--size",
            "48x48", "--terms", "all", "-o", out,
        ];
        let file = p("lone.ltm");
        args[1] = file.as_str();
        args.extend_from_slice(extra);
        ltm(&args)
    };
    let read = |n: &str| ltm_relight::Image::read_exr(&d.join(n)).unwrap();
    let (ok, stderr) = render(&p("transport.exr"), &env, &[]);
    assert!(ok, "{stderr}");
    // The same Lambertian material drawn by wavelet rotation alone, every
    // BRDF term kept: the two methods see one lighting and agree (0.39 %
    // when measured; 25 % and 43 % with the map turned by yaw 180° or
    // pitch 90° in one of them).
    let cache = p("rot.bin");
    let glossy = [
        "--brdf",
        "lambert:0.7/0.6/0.5",
        "--shading",
        "glossy",
        "--glossy-n",
        "32",
        "--normals",
        "16",
        "--brdf-keep",
        "1",
        "--rotation-cache",
        cache.as_str(),
    ];
    let (ok, stderr) = render(&p("rotation.exr"), &env, &glossy);
    assert!(ok, "{stderr}");
    assert!(stderr.contains("built and cached"), "{stderr}");
    let (transport, rotation) = (read("transport.exr"), read("rotation.exr"));
    let err = ltm_relight::relative_l2(&rotation, &transport).unwrap();
    eprintln!("rotation against transport: {:.2} %", err * 100.0);
    assert!(err < 0.015, "relative L2 {err}");
    // The same albedo as a measured table in the MERL layout draws the same
    // picture (a constant BRDF is exact in every bin but the grazing ones
    // whose centre lies below the horizon, unmeasured as in the database:
    // 0.026 % when measured).
    let table = ltm_relight::rotation::MeasuredBrdf::tabulate(
        "clay",
        |_, _| [0.7, 0.6, 0.5].map(|a| a / std::f64::consts::PI),
        &ltm_codec::Limits::default(),
    )
    .unwrap();
    std::fs::write(d.join("clay.binary"), table.to_bytes()).unwrap();
    let merl = format!("merl:{}", p("clay.binary"));
    let mut measured = glossy;
    measured[1] = merl.as_str();
    let (ok, stderr) = render(&p("measured.exr"), &env, &measured);
    assert!(ok && stderr.contains("glossy merl:"), "{stderr}");
    let same = ltm_relight::relative_l2(&read("measured.exr"), &rotation).unwrap();
    assert!(same < 1e-3, "measured against analytic Lambert: {same}");
    // Turned lighting is far off: the map is not symmetric.
    let (ok, stderr) = render(
        &p("turned.exr"),
        &env,
        &[&glossy[..], &["--rotate", "180,0,0"]].concat(),
    );
    assert!(ok && stderr.contains("read from the cache"), "{stderr}");
    let turned = ltm_relight::relative_l2(&read("turned.exr"), &transport).unwrap();
    assert!(turned > 10.0 * err, "{turned} against {err}");
    // A glossy coat adds light, and only where the surface is.
    let studio = env_map();
    // A cache folder keeps one file per setting, and the second run reads
    // it.
    let folder = p("rotations");
    std::fs::create_dir(&folder).unwrap();
    let coat_args = [
        "--brdf",
        "ggx:0.3",
        "--glossy-n",
        "32",
        "--rotation-cache",
        folder.as_str(),
    ];
    for expect in ["built and cached", "read from the cache"] {
        let (ok, stderr) = render(&p("coat.exr"), &studio, &coat_args);
        assert!(
            ok && stderr.contains("glossy ggx:0.3,f0=0.9 (Sum") && stderr.contains(expect),
            "{stderr}"
        );
    }
    let kept = Path::new(&folder).join("rotation-n32-normals32-ss16-t1.bin");
    assert!(kept.is_file(), "{}", kept.display());
    let coat = read("coat.exr");
    let (ok, stderr) = render(&p("studio.exr"), &studio, &[]);
    assert!(ok, "{stderr}");
    let transport = read("studio.exr");
    let mut brighter = 0;
    for (c, t) in coat.data.iter().zip(&transport.data) {
        for k in 0..3 {
            assert!(c[k] >= t[k] - 1e-6 && c[k].is_finite(), "{c:?} < {t:?}");
            assert_eq!(t[k] == 0.0, c[k] == 0.0, "{c:?} against {t:?}");
        }
        brighter += usize::from(c[0] > t[0] * 1.01);
    }
    assert!(brighter > 100, "{brighter} pixels gained light");
    // Bad specs, and a cache path that is the input or someone's file,
    // are refused; neither file changes.
    let (lone, mine) = (p("lone.ltm"), p("transport.exr"));
    let before = [&lone, &mine].map(|f| std::fs::read(f).unwrap());
    for (extra, expect) in [
        (
            &["--brdf", "velvet:1"][..],
            &["unknown BRDF 'velvet'", "ggx:ALPHA"][..],
        ),
        (&["--brdf", "ggx:2"], &["0.01..=1"]),
        (
            &["--brdf", "ggx:0.2", "--glossy-n", "12"],
            &["power of two"],
        ),
        (
            &["--brdf", "ggx:0.2", "--rotation-cache", &lone],
            &["refusing to overwrite an input"],
        ),
        (
            &["--brdf", "ggx:0.2", "--rotation-cache", &mine],
            &["not a rotation cache", "refusing to replace it"],
        ),
        (&["--shading", "glossy"], &["--brdf"]),
        (&["--brdf", "merl:/no/such.binary"], &["/no/such.binary"]),
        (
            &["--brdf", "ggx:0.2", "--brdf-keep", "0"],
            &["kept BRDF fraction", "(0, 1]"],
        ),
        (&["--brdf", "ggx:0.2", "--normals", "0"], &["1..=256"]),
    ] {
        let out = p("bad.exr");
        let (ok, stderr) = render(&out, &env, extra);
        assert!(!ok, "{extra:?} succeeded");
        for e in expect {
            assert!(stderr.contains(e), "{extra:?}: {stderr}");
        }
        assert!(!Path::new(&out).exists());
    }
    assert_eq!([&lone, &mine].map(|f| std::fs::read(f).unwrap()), before);
}

/// An atlas bake prints one texel density per measure: a one-mesh atlas
/// the valid texels per unit area alone, an atlas of the mesh and the
/// ground quad also each part's charts.
#[test]
fn atlas_bakes_print_one_density_per_measure() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("sphere.obj"), sphere_obj(2, "")).unwrap();
    let densities = |texture: &str, name: &str| {
        let scene = write_scene(d, &format!("{name}.toml"), "sphere.obj", texture);
        let raw = d.join(format!("{name}.raw"));
        let (ok, stderr) = ltm(&["bake", &scene, "-o", raw.to_str().unwrap()]);
        assert!(ok, "{stderr}");
        let lines: Vec<String> = stderr
            .lines()
            .filter(|l| l.contains("per unit area"))
            .map(str::to_string)
            .collect();
        (lines, stderr)
    };
    let atlas = |mesh: &str| format!("\n[texture]\nmesh = {mesh}\nsize = 32\nspp = 1\n");
    let (one, stderr) = densities(&atlas("0"), "one");
    assert_eq!(one.len(), 1, "{stderr}");
    assert!(one[0].contains("valid texels per unit area"), "{stderr}");
    let (all, stderr) = densities(&atlas("\"all\""), "all");
    assert_eq!(all.len(), 3, "{stderr}");
    assert_eq!(
        all.iter().filter(|l| l.contains("charts cover")).count(),
        2,
        "{stderr}"
    );
}
