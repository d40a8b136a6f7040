//! `ltm view`'s HTTP API, against the binary: frames equal `ltm relight`'s
//! at the same settings, the exact view's error equals `ltm relight
//! --reference`'s, bad parameters get 400, malformed requests never bring
//! the server down, and concurrent frames are bounded.

use crate::view_support;

use proptest::prelude::*;
use view_support::*;

fn server() -> Server {
    let s = scene();
    Server::start(&[
        s.ltm.to_str().unwrap(),
        s.ltm2.to_str().unwrap(),
        "--env",
        map("interior.exr").to_str().unwrap(),
        "--env",
        map("sunset.exr").to_str().unwrap(),
        "--reference",
        s.raw.to_str().unwrap(),
    ])
}

#[test]
fn info_lists_files_and_maps_by_name_only() {
    let srv = server();
    let r = srv.get("/api/info");
    assert_eq!(r.status, 200);
    let v: serde_json::Value = serde_json::from_slice(&r.body).unwrap();
    assert_eq!(v["files"][0]["name"], "t.ltm");
    assert_eq!(v["files"][1]["mode"], "2d");
    assert_eq!(v["files"][0]["width"], 24);
    assert_eq!(v["files"][0]["height"], 20);
    assert_eq!(v["files"][0]["lights"], 96);
    assert_eq!(v["files"][0]["layout"], "image");
    let e = v["files"][0]["matrix_error"].as_f64().unwrap();
    assert!(e > 0.0 && e <= 0.05, "{e}");
    assert_eq!(v["maps"][1]["name"], "sunset.exr");
    assert_eq!(v["maps"].as_array().unwrap().len(), 2);
    assert_eq!(v["reference"], "t.raw");
    // No folder of any file is given away.
    assert!(!r.text().contains('/'), "{}", r.text());
    let page = srv.get("/");
    assert_eq!(page.status, 200);
    assert!(page.text().contains("/view.js"));
    assert_eq!(srv.get("/view.js").status, 200);
}

#[test]
fn frames_match_ltm_relight() {
    let srv = server();
    let s = scene();
    for (file, path, map_i, map_name, rot, n, w) in [
        (0, &s.ltm, 0, "interior.exr", "0,0,0", 96, "unweighted"),
        (0, &s.ltm, 1, "sunset.exr", "30,-15,5", 20, "transport"),
        (1, &s.ltm2, 1, "sunset.exr", "-120.5,40,0", 7, "area"),
        (1, &s.ltm2, 0, "interior.exr", "400,0,-90", 1, "unweighted"),
    ] {
        let r: Vec<&str> = rot.split(',').collect();
        let q = format!(
            "/api/frame?file={file}&map={map_i}&yaw={}&pitch={}&roll={}&n={n}&weighting={w}",
            r[0], r[1], r[2]
        );
        let got = srv.get(&q);
        assert_eq!(got.status, 200, "{q}: {}", got.text());
        let (width, height, values) = got.frame();
        assert_eq!((width, height), (24, 20));
        let (want, json) = relight(path, &map(map_name), rot, n, w, None);
        assert_eq!(values.len(), want.len());
        for (i, (a, b)) in values.iter().zip(&want).enumerate() {
            assert!(
                (a - b).abs() <= f16_tolerance(*b),
                "{q}: value {i}: {a} vs {b}"
            );
        }
        assert_eq!(
            got.header("x-lights"),
            Some(json["lights"].to_string().as_str()),
            "{q}"
        );
        assert_eq!(
            got.header("x-nonzeros"),
            Some(json["nonzeros"].to_string().as_str()),
            "{q}"
        );
        let ms: f64 = got.header("x-frame-ms").unwrap().parse().unwrap();
        assert!(ms >= 0.0);
    }
}

#[test]
fn exact_error_matches_ltm_relight_reference() {
    let srv = server();
    let s = scene();
    let q = "file=0&map=1&yaw=45&pitch=10&roll=0&n=12&weighting=transport";
    // Before the exact image is computed, frames carry no error.
    assert_eq!(srv.get(&format!("/api/frame?{q}")).header("x-error"), None);
    let exact = srv.get(&format!("/api/exact?{q}"));
    assert_eq!(exact.status, 200, "{}", exact.text());
    let err: f64 = exact.header("x-error").unwrap().parse().unwrap();
    let exr = reference(&map("sunset.exr"), "45,10,0");
    let want_img = ltm_relight::Image::read_exr(&exr).unwrap();
    let (_, _, got_img) = exact.frame();
    for (a, b) in got_img.iter().zip(want_img.data.iter().flatten()) {
        assert!((a - b).abs() <= f16_tolerance(*b), "exact: {a} vs {b}");
    }
    let (_, json) = relight(
        &s.ltm,
        &map("sunset.exr"),
        "45,10,0",
        12,
        "transport",
        Some(&exr),
    );
    let want = json["relative_error"].as_f64().unwrap();
    assert!(
        (err - want).abs() <= 1e-6 * want.max(1e-3),
        "{err} vs {want}"
    );
    // Now cached: frames carry the error too.
    let again = srv.get(&format!("/api/frame?{q}"));
    let e2: f64 = again.header("x-error").unwrap().parse().unwrap();
    assert!((e2 - want).abs() <= 1e-6 * want.max(1e-3));
}

/// `light=draft` frames come from the prefiltered resampling until the
/// exact light is cached; they are close to the exact frame.
#[test]
fn draft_lights_are_close_and_give_way_to_exact_ones() {
    let srv = server();
    let q = "file=0&map=0&yaw=63.5&pitch=-20&roll=4&n=96";
    let draft = srv.get(&format!("/api/frame?{q}&light=draft"));
    assert_eq!(draft.status, 200, "{}", draft.text());
    assert_eq!(draft.header("x-light"), Some("draft"));
    let exact = srv.get(&format!("/api/frame?{q}"));
    assert_eq!(exact.header("x-light"), Some("exact"));
    let (_, _, a) = draft.frame();
    let (_, _, b) = exact.frame();
    let e = frame_distance(&a, &b);
    // At n = 4 a texel spans 22°, and the draft's prefilter moves up to a
    // third of a texel's light across its edges: about 13 % here (at n = 32
    // the same blur spans under 1°; see README's viewer figures).
    assert!(e > 0.0 && e < 0.2, "draft against exact: {e}");
    // Once the exact light is cached, a draft request gets it.
    let again = srv.get(&format!("/api/frame?{q}&light=draft"));
    assert_eq!(again.header("x-light"), Some("exact"));
    assert_eq!(again.body, exact.body);
}

#[test]
fn bad_parameters_get_400_with_a_message() {
    let srv = server();
    for (q, needle) in [
        ("file=2&map=0&n=1", "file '2' is out of range"),
        ("file=0&map=9&n=1", "map '9' is out of range (valid: 0..=1)"),
        ("file=0&map=0&n=0", "n '0' is out of range (valid: 1..=96"),
        ("file=0&map=0&n=97", "n '97'"),
        ("file=0&map=0&n=5&yaw=nan", "yaw 'nan'"),
        ("file=0&map=0&n=5&pitch=-inf", "pitch '-inf'"),
        ("file=0&map=0&n=5&roll=1e20", "roll '1e20'"),
        (
            "file=0&map=0&n=5&weighting=best",
            "unknown weighting 'best'",
        ),
        (
            "file=0&map=0&n=5&env=..%2F..%2Fetc%2Fpasswd",
            "unknown parameter 'env'",
        ),
        ("file=0&map=0&n=5&seq=3", "client and seq go together"),
        ("file=0&map=0&n=5&client=%00x&seq=3", "letters and digits"),
        (
            "file=0&map=0&n=5&light=fast",
            "light 'fast' is not exact or draft",
        ),
    ] {
        for endpoint in ["frame", "exact"] {
            let r = srv.get(&format!("/api/{endpoint}?{q}"));
            assert_eq!(r.status, 400, "{q}");
            assert!(r.text().contains(needle), "{q}: {}", r.text());
        }
    }
    for endpoint in ["surface", "mesh"] {
        let r = srv.get(&format!("/api/{endpoint}?file=0"));
        assert_eq!(r.status, 400);
        assert!(r.text().contains("image-space"), "{}", r.text());
    }
    assert_eq!(srv.get("/api/info?x=1").status, 400);
    assert_eq!(srv.get("/etc/passwd").status, 404);
    assert_eq!(srv.get("/../Cargo.toml").status, 404);
    let long = format!("/api/frame?file=0&map=0&n=1&yaw={}", "1".repeat(3000));
    assert_eq!(srv.get(&long).status, 414);
    let post = srv.raw(b"POST /api/frame?file=0&map=0&n=1 HTTP/1.1\r\nHost: localhost\r\nContent-Length: 3\r\nConnection: close\r\n\r\nabc");
    assert!(String::from_utf8_lossy(&post).starts_with("HTTP/1.1 405"));
    let rebound =
        srv.raw(b"GET /api/info HTTP/1.1\r\nHost: evil.example\r\nConnection: close\r\n\r\n");
    assert!(String::from_utf8_lossy(&rebound).starts_with("HTTP/1.1 403"));
}

#[test]
fn stale_requests_of_a_client_are_dropped() {
    let srv = server();
    let q = "file=0&map=0&n=5";
    assert_eq!(
        srv.get(&format!("/api/frame?{q}&client=abc&seq=10")).status,
        200
    );
    let stale = srv.get(&format!("/api/frame?{q}&client=abc&seq=9"));
    assert_eq!(stale.status, 204);
    assert_eq!(stale.header("x-stale"), Some("1"));
    // Other clients are independent.
    assert_eq!(
        srv.get(&format!("/api/frame?{q}&client=other&seq=1"))
            .status,
        200
    );
    assert_eq!(
        srv.get(&format!("/api/frame?{q}&client=abc&seq=11")).status,
        200
    );
}

#[test]
fn concurrent_clients_get_frames_or_busy_and_the_server_stays_up() {
    let s = scene();
    let mut srv = Server::start(&[
        s.ltm.to_str().unwrap(),
        "--env",
        map("interior.exr").to_str().unwrap(),
        "--slots",
        "1",
    ]);
    let q = "/api/frame?file=0&map=0&yaw=10&n=96";
    let want = srv.get(q).frame();
    let statuses: Vec<(u16, Option<_>)> = std::thread::scope(|sc| {
        let handles: Vec<_> = (0..12)
            .map(|_| {
                sc.spawn(|| {
                    let r = srv.get(q);
                    let f = (r.status == 200).then(|| r.frame());
                    (r.status, f)
                })
            })
            .collect();
        handles.into_iter().map(|h| h.join().unwrap()).collect()
    });
    for (status, frame) in &statuses {
        assert!(*status == 200 || *status == 503, "status {status}");
        if let Some(f) = frame {
            assert_eq!(f, &want, "a frame made under load differs");
        }
    }
    // Clients that connect and go away mid-request free what they held.
    for _ in 0..8 {
        let mut c = std::net::TcpStream::connect(&srv.addr).unwrap();
        use std::io::Write;
        let _ =
            c.write_all(b"GET /api/frame?file=0&map=0&n=96 HTTP/1.1\r\nHost: localhost\r\n\r\n");
        drop(c);
    }
    assert!(srv.is_alive());
    // Their frames may still hold the slot: the next request gets 503 until
    // they end, then the same frame.
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(60);
    loop {
        let r = srv.get(q);
        if r.status == 200 {
            assert_eq!(r.frame(), want);
            break;
        }
        assert_eq!(r.status, 503, "{}", r.text());
        assert!(
            std::time::Instant::now() < deadline,
            "the slot was never freed"
        );
        std::thread::yield_now();
    }
}

/// Random query strings and random bytes never bring the server down: each
/// gets an HTTP answer (or none, for bytes that are not HTTP), and the
/// server answers a good request afterwards.
#[test]
fn malformed_requests_never_panic() {
    use proptest::test_runner::{Config, TestRunner};
    let srv = server();
    let mut runner = TestRunner::new(Config {
        cases: 48,
        ..Config::default()
    });
    let strategy = (
        "[a-z=&%0-9.eE+\\-]{0,120}",
        proptest::collection::vec(any::<u8>(), 0..600),
    );
    runner
        .run(&strategy, |(query, junk)| {
            let r = srv.get(&format!("/api/frame?{query}"));
            prop_assert!(
                [200, 204, 400, 503].contains(&r.status),
                "{}: {}",
                r.status,
                r.text()
            );
            let _ = srv.raw(&junk);
            let mut req = b"GET /api/exact?".to_vec();
            req.extend_from_slice(&junk);
            req.extend_from_slice(b" HTTP/1.1\r\nHost: localhost\r\nConnection: close\r\n\r\n");
            let _ = srv.raw(&req);
            prop_assert_eq!(srv.get("/api/info").status, 200);
            Ok(())
        })
        .unwrap();
}

/// A texture-space file: the page gets its geometry image, and its frames
/// (the relit texture) equal `ltm relight`'s.
#[test]
fn texture_files_serve_their_surface_and_relit_texture() {
    let dir = tempfile::tempdir().unwrap();
    let tex = blob_texture(dir.path());
    let p = |p: &std::path::Path| p.to_str().unwrap().to_string();
    let srv = Server::start(&[&p(&tex), "--env", &p(&map("interior.exr"))]);
    let info: serde_json::Value = serde_json::from_slice(&srv.get("/api/info").body).unwrap();
    assert_eq!(info["files"][0]["layout"], "texture");
    assert_eq!(info["files"][0]["parameterization"], "sphere");
    let r = srv.get("/api/surface?file=0");
    assert_eq!(r.status, 200, "{}", r.text());
    let b = &r.body;
    assert_eq!(&b[..4], b"LTMS");
    assert_eq!(b.len(), 16 + 256 * 13);
    let valid = &b[16 + 256 * 12..];
    assert!(valid.iter().all(|&v| v <= 1) && valid.iter().filter(|&&v| v == 1).count() > 128);
    let xyz: Vec<f32> = b[16..16 + 256 * 12]
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
        .collect();
    assert!(xyz.iter().all(|v| v.is_finite() && v.abs() < 10.0));
    // What `ltm render` draws: the grid's vertices (one per texel, the
    // texel's centre as texture coordinate), triangles, reaches and folds.
    let r = srv.get("/api/mesh?file=0");
    assert_eq!(r.status, 200, "{}", r.text());
    let b = &r.body;
    assert_eq!(&b[..4], b"LTMG");
    let u = |o: usize| u32::from_le_bytes(b[o..o + 4].try_into().unwrap()) as usize;
    let (v, t) = (u(4), u(8));
    assert_eq!((v, u(12)), (256, 1));
    assert!(t > 128, "{t} triangles");
    assert_eq!(b.len(), 16 + v * 20 + t * 17);
    let f = |o: usize| f32::from_le_bytes(b[o..o + 4].try_into().unwrap());
    assert_eq!(
        &b[16..16 + v * 12],
        &srv.get("/api/surface?file=0").body[16..16 + v * 12]
    );
    let uv = 16 + v * 12;
    assert_eq!((f(uv + 17 * 8), f(uv + 17 * 8 + 4)), (1.5, 1.5));
    let tri = uv + v * 8;
    assert!((0..3 * t).all(|k| u(tri + 4 * k) < v));
    let reach = tri + t * 12;
    assert!((0..t).all(|k| f(reach + 4 * k) == f32::INFINITY));
    let folded = &b[reach + 4 * t..];
    assert!(folded.iter().all(|&x| x <= 1) && folded.contains(&1));
    let got = srv.get("/api/frame?file=0&map=0&yaw=20&n=24");
    assert_eq!(got.status, 200, "{}", got.text());
    let (w, h, values) = got.frame();
    assert_eq!((w, h), (16, 16));
    let (want, _) = relight(&tex, &map("interior.exr"), "20,0,0", 24, "unweighted", None);
    for (a, b) in values.iter().zip(&want) {
        assert!((a - b).abs() <= f16_tolerance(*b), "{a} vs {b}");
    }
    assert!(want.iter().any(|&v| v > 0.0));
}

/// A 16² sphere-layout texture over a closed procedural blob, baked with
/// 6·2² lights and compressed (the sphere parameterization of a scanned
/// mesh would cost a test minutes).
fn blob_texture(dir: &std::path::Path) -> std::path::PathBuf {
    texture_file(dir, ltm_testkit::TEXTURE_SPHERE_16)
}

/// Glossy materials (`ltm view --brdf`; that a frame is `ltm render
/// --brdf`'s from the eye is checked pixel for pixel in the browser test):
/// a new eye or material re-runs step 2 only, a new lighting step 1 too, a
/// view-independent material gives one texture from every eye, and misuse
/// gets 400.
#[test]
fn glossy_frames_rerun_step_1_only_for_a_new_lighting() {
    let dir = tempfile::tempdir().unwrap();
    let tex = blob_texture(dir.path());
    let p = |p: &std::path::Path| p.to_str().unwrap().to_string();
    let (tex, image, env) = (p(&tex), p(&scene().ltm), p(&map("interior.exr")));
    let srv = Server::start(&[
        &tex,
        &image,
        "--env",
        &env,
        "--brdf",
        "ggx:0.3",
        "--brdf",
        "lambert:0.5",
        "--glossy-n",
        "16",
    ]);
    let info: serde_json::Value = serde_json::from_slice(&srv.get("/api/info").body).unwrap();
    assert_eq!(info["brdfs"], serde_json::json!(["ggx:0.3", "lambert:0.5"]));
    assert_eq!(info["glossy_n"], 16);
    let base = "/api/frame?file=0&map=0&yaw=20&n=24";
    let get = |extra: &str| {
        let r = srv.get(&format!("{base}{extra}"));
        assert_eq!(r.status, 200, "{extra}: {}", r.text());
        let ms = |h: &str| r.header(h).map(|v| v.parse::<f64>().unwrap());
        let times = [ms("x-glossy-setup-ms"), ms("x-step1-ms"), ms("x-step2-ms")];
        (r.frame().2, times)
    };
    let (baked, none) = get("");
    assert_eq!(none, [None; 3]);
    let (front, t) = get("&brdf=1&eye=0,0.5,3");
    assert!(
        t[0].unwrap() > 0.0 && t[1].unwrap() > 0.0 && t[2].unwrap() > 0.0,
        "{t:?}"
    );
    let (side, t) = get("&brdf=1&eye=3,0.5,0");
    assert_eq!(
        (t[0], t[1]),
        (Some(0.0), Some(0.0)),
        "a new eye: step 2 only"
    );
    // The reflection adds light, and moves with the eye.
    let added = |g: &[f32]| g.iter().zip(&baked).map(|(a, b)| a - b).collect::<Vec<_>>();
    let (a, b) = (added(&front), added(&side));
    assert!(
        a.iter().chain(&b).all(|&d| d >= -1e-3),
        "a glossy frame is brighter"
    );
    assert!(a.iter().sum::<f32>() > 0.0);
    assert!(frame_distance(&a, &b) > 0.05, "{}", frame_distance(&a, &b));
    // Eyes in between, then the first again: the same frame.
    for k in 1..12 {
        let a = f64::from(k) * 0.13;
        get(&format!(
            "&brdf=1&eye={},0.5,{}",
            3.0 * a.sin(),
            3.0 * a.cos()
        ));
    }
    assert_eq!(get("&brdf=1&eye=0,0.5,3").0, front);
    // A new material keeps the local lightings: no step 1.
    let (lambert_front, t) = get("&brdf=2&eye=0,0.5,3");
    assert_eq!(t[1], Some(0.0), "a new material: no step 1");
    assert!(t[0].unwrap() > 0.0, "its slices are built");
    let (lambert_side, t) = get("&brdf=2&eye=3,0.5,0");
    assert_eq!(t[1], Some(0.0));
    assert_eq!(
        lambert_front, lambert_side,
        "Lambert looks the same from every eye"
    );
    assert_ne!(lambert_front, front);
    // Back to the first material: its frame, with no step 1.
    let (again, t) = get("&brdf=1&eye=0,0.5,3");
    assert_eq!(again, front);
    assert_eq!(t[1], Some(0.0));
    // A new lighting: step 1.
    let r = srv.get("/api/frame?file=0&map=0&yaw=21&n=24&brdf=1&eye=0,0.5,3");
    assert_eq!(r.status, 200, "{}", r.text());
    assert!(r.header("x-step1-ms").unwrap().parse::<f64>().unwrap() > 0.0);
    for (q, says) in [
        (
            "file=0&map=0&n=4&brdf=3&eye=0,0,3",
            "brdf '3' is out of range (valid: 0..=2)",
        ),
        ("file=0&map=0&n=4&brdf=1", "brdf needs eye"),
        ("file=0&map=0&n=4&brdf=1&eye=0,0,inf", "is not x,y,z"),
    ] {
        let r = srv.get(&format!("/api/frame?{q}"));
        assert_eq!(r.status, 400, "{q}");
        assert!(r.text().contains(says), "{q}: {}", r.text());
    }
    image_rows_take_the_material_from_their_own_eye(&srv, &info, &image, &env);
}

/// The image-space file of the glossy test: `/api/info` gives the eye its
/// surface records fix (the scene file's camera), and a glossy frame is
/// `ltm relight --brdf`'s, shaded from that eye whatever the request's.
fn image_rows_take_the_material_from_their_own_eye(
    srv: &Server,
    info: &serde_json::Value,
    image: &str,
    env: &str,
) {
    assert_eq!(info["files"][0]["eye"], serde_json::Value::Null);
    let eye: Vec<f64> = serde_json::from_value(info["files"][1]["eye"].clone()).unwrap();
    let want = [0.2, 1.45, 5.0];
    assert!(
        eye.iter().zip(want).all(|(a, b)| (a - b).abs() < 1e-5),
        "{eye:?}"
    );
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("g.exr");
    let o = out.to_str().unwrap();
    let args = [
        "relight",
        image,
        "--env",
        env,
        "--rotate=20,0,0",
        "--terms",
        "24",
    ];
    ltm(&[
        &args[..],
        &[
            "--weighting",
            "unweighted",
            "--brdf",
            "ggx:0.3",
            "--glossy-n",
            "16",
            "-o",
            o,
        ],
    ]
    .concat());
    let want: Vec<f32> = ltm_relight::Image::read_exr(&out)
        .unwrap()
        .data
        .iter()
        .flatten()
        .copied()
        .collect();
    for eye in ["0.2,1.45,5", "9,-9,9"] {
        let r = srv.get(&format!(
            "/api/frame?file=1&map=0&yaw=20&n=24&brdf=1&eye={eye}"
        ));
        assert_eq!(r.status, 200, "{}", r.text());
        let (_, _, got) = r.frame();
        assert_eq!(got.len(), want.len());
        for (a, b) in got.iter().zip(&want) {
            assert!(
                (a - b).abs() <= f16_tolerance(*b) + 1e-5 * b.abs(),
                "{a} vs {b}"
            );
        }
    }
    let plain = srv.get("/api/frame?file=1&map=0&yaw=20&n=24").frame().2;
    assert!(
        frame_distance(&plain, &want) > 1e-3,
        "the material adds nothing"
    );
}

/// `/api/map`: the map's preview (256 × 128), box-filtered (its mean is the
/// map's), and rotated as the frames' lighting is: a yaw of 180 degrees
/// moves every pixel by half the width, 360 degrees is the identity; bad
/// parameters get 400.
#[test]
fn map_previews_are_the_maps_rotated() {
    let srv = server();
    let env = ltm_relight::EnvMap::load(&map("sunset.exr")).unwrap();
    let get = |q: &str| {
        let r = srv.get(&format!("/api/map?{q}"));
        assert_eq!(r.status, 200, "{q}: {}", r.text());
        r.frame()
    };
    let (w, h, still) = get("map=1");
    assert_eq!((w, h), (256, 128));
    let mean = |v: &[f32]| v.iter().map(|x| f64::from(*x)).sum::<f64>() / v.len() as f64;
    let want = env
        .data()
        .iter()
        .flatten()
        .map(|x| f64::from(*x))
        .sum::<f64>()
        / (3 * env.data().len()) as f64;
    let got = mean(&still);
    assert!(
        (got - want).abs() <= 2e-3 * want,
        "preview mean {got}, map mean {want}"
    );
    assert_eq!(get("map=1&yaw=360").2, still);
    let (_, _, half) = get("map=1&yaw=180");
    for y in [10, 64, 100] {
        for x in [0, 37, 200] {
            let shifted = (x + w / 2) % w;
            for c in 0..3 {
                assert_eq!(
                    half[3 * (y * w + x) + c],
                    still[3 * (y * w + shifted) + c],
                    "pixel ({x}, {y})"
                );
            }
        }
    }
    for (q, needle) in [
        ("map=2", "map '2' is out of range"),
        ("map=0&yaw=nan", "yaw 'nan'"),
        ("map=0&n=3", "unknown parameter 'n'"),
    ] {
        let r = srv.get(&format!("/api/map?{q}"));
        assert_eq!(r.status, 400, "{q}");
        assert!(r.text().contains(needle), "{q}: {}", r.text());
    }
}
