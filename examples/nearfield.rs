//! A near-field image: every pixel of a scene's camera baked over a light
//! plane's face (`Scene::plane_row`) and lit by a textured area light
//! (`ltm::relight::nearfield`). The input of the Mitsuba check
//! `tools/validate/mitsuba_nearfield.py`, which bakes with the scene's own
//! direction samples and the rows' mean hit points. The command line does
//! the same from a file: a `[light_plane]` in the scene, `ltm bake`, `ltm
//! compress`, `ltm relight --area-light`.
//!
//! ```text
//! cargo run --release --example nearfield -- SCENE.toml \
//!     --plane OX,OY,OZ,XX,XY,XZ,YX,YY,YZ --texture W,H,TEXTURE.f32 \
//!     --center X,Y --size W,H [--intensity I] [--order 32] [--side 4] \
//!     [--source-share 1] [--target-share 1] -o OUT.f32 [--coverage OUT.u8] \
//!     [--points OUT.points]
//! ```
//!
//! Grey scenes (Lambertian) and RGB ones (glossy materials) both work: an
//! RGB row's channel `c` is lit by the light's channel `c`.
//!
//! `TEXTURE.f32` is `H × W × 3` little-endian f32 radiance, row 0 at the
//! light's −y edge; `OUT.f32` is the image, `height × width × 3` f32 with
//! row 0 at the top. The plane's lit side is `x × y`. `OUT.u8` holds one
//! byte per pixel: 2 when the whole light rectangle lies inside the
//! pixel's face, 1 when part of it lies outside (grazing light the face
//! leaves out), 0 when the pixel sees no surface or is behind the plane.
//! `OUT.points` holds each pixel's surface point, `x, y, z` f32 (NaN for a
//! miss), from which silhouettes can be found.

use glam::DVec3;
use ltm::bake::{LightPlane, Scene, SceneDesc};
use ltm::relight::nearfield::{
    transport_coefficients, LightTexture, Placement, PlaneFace, Propagator, Receiver,
    SourceCoefficients, Targets,
};
use rayon::prelude::*;
use std::collections::HashMap;
use std::error::Error;
use std::time::Instant;

fn numbers(
    args: &HashMap<String, String>,
    key: &str,
    count: usize,
) -> Result<Vec<f64>, Box<dyn Error>> {
    let text = args
        .get(key)
        .ok_or_else(|| format!("--{key} is required"))?;
    let values = text
        .split(',')
        .map(str::parse)
        .collect::<Result<Vec<f64>, _>>()?;
    if values.len() != count {
        return Err(format!("--{key} takes {count} numbers, got {text}").into());
    }
    Ok(values)
}

fn number(args: &HashMap<String, String>, key: &str, default: f64) -> Result<f64, Box<dyn Error>> {
    Ok(args
        .get(key)
        .map(|v| v.parse())
        .transpose()?
        .unwrap_or(default))
}

fn texture(spec: &str) -> Result<LightTexture, Box<dyn Error>> {
    let mut parts = spec.splitn(3, ',');
    let (w, h, path) = match (parts.next(), parts.next(), parts.next()) {
        (Some(w), Some(h), Some(p)) => (w.parse::<usize>()?, h.parse::<usize>()?, p),
        _ => return Err("--texture takes W,H,PATH".into()),
    };
    let bytes = std::fs::read(path)?;
    if bytes.len() != w * h * 12 {
        return Err(format!("{path}: {} bytes, not {w}x{h}x3 f32", bytes.len()).into());
    }
    let values: Vec<f32> = bytes
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    Ok(LightTexture::new(
        w,
        h,
        values.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
    )?)
}

/// A baked floor of the image: the point's receiver, albedo (grey
/// transport), transport coefficients per channel (one list for grey
/// transport, three for RGB) and world position; `None` for a miss.
type Row = Option<(Receiver, [f32; 3], Vec<Vec<(u32, f32)>>, DVec3)>;

/// Every pixel's row over the plane's face, in parallel.
fn bake_rows(scene: &Scene, plane: &LightPlane, face: PlaneFace) -> Result<Vec<Row>, String> {
    let channels = scene.channels() as usize;
    (0..scene.dims().pixels())
        .into_par_iter()
        .map(|p| {
            let mut row = vec![0.0f32; face.order * face.order * channels];
            let mut albedo = [0.0f32; 3];
            let info = scene
                .plane_row(p, plane, face.order, face.side, &mut row, &mut albedo)
                .map_err(|e| e.to_string())?;
            let Some(point) = info.point else {
                return Ok(None);
            };
            let (depth, position) = plane.locate(point);
            let transport = (0..channels)
                .map(|c| {
                    let plane: Vec<f32> = row.iter().skip(c).step_by(channels).copied().collect();
                    transport_coefficients(&plane, face.order).map_err(|e| e.to_string())
                })
                .collect::<Result<Vec<_>, String>>()?;
            Ok(Some((
                Receiver { depth, position },
                albedo,
                transport,
                point,
            )))
        })
        .collect()
}

/// The relit image, chunks of rows in parallel with a propagator each.
fn relight(
    rows: &[Row],
    face: PlaneFace,
    source: &SourceCoefficients,
    placement: &Placement,
    targets: Targets,
) -> Vec<[f32; 3]> {
    rows.par_chunks(256)
        .flat_map_iter(|chunk| {
            let mut propagator = Propagator::new(face).expect("checked face");
            chunk
                .iter()
                .map(|row| {
                    let Some((receiver, albedo, transport, _)) = row else {
                        return [0.0; 3];
                    };
                    if !propagator
                        .prepare(source, placement, receiver, targets)
                        .unwrap_or(false)
                    {
                        return [0.0; 3];
                    }
                    if let [grey] = &transport[..] {
                        let b = propagator.shade(grey);
                        [0, 1, 2].map(|c| (b[c] * f64::from(albedo[c])).max(0.0) as f32)
                    } else {
                        [0, 1, 2].map(|c| propagator.shade(&transport[c])[c].max(0.0) as f32)
                    }
                })
                .collect::<Vec<_>>()
        })
        .collect()
}

/// The optional `--coverage` and `--points` files.
fn write_extras(
    args: &HashMap<String, String>,
    rows: &[Row],
    face: PlaneFace,
    placement: &Placement,
) -> Result<(), Box<dyn Error>> {
    if let Some(path) = args.get("coverage") {
        let inside = |r: &Receiver| {
            (0..2).all(|a| {
                let reach = 0.5 * r.depth * face.side;
                let half = 0.5 * placement.size[a];
                let (lo, hi) = (placement.center[a] - half, placement.center[a] + half);
                lo >= r.position[a] - reach && hi <= r.position[a] + reach
            })
        };
        let coverage: Vec<u8> = rows
            .iter()
            .map(|row| match row {
                Some((r, _, _, _)) if r.depth > 0.0 => 1 + u8::from(inside(r)),
                _ => 0,
            })
            .collect();
        std::fs::write(path, coverage)?;
    }
    if let Some(path) = args.get("points") {
        let points: Vec<u8> = rows
            .iter()
            .flat_map(|row| {
                let p = row
                    .as_ref()
                    .map_or([f32::NAN; 3], |r| r.3.as_vec3().to_array());
                p.into_iter().flat_map(f32::to_le_bytes)
            })
            .collect();
        std::fs::write(path, points)?;
    }
    Ok(())
}

fn main() -> Result<(), Box<dyn Error>> {
    let argv: Vec<String> = std::env::args().skip(1).collect();
    let scene_path = argv
        .first()
        .ok_or("usage: nearfield SCENE.toml --plane ... -o OUT.f32")?;
    let args: HashMap<String, String> = argv[1..]
        .chunks(2)
        .map(|kv| {
            (
                kv[0].trim_start_matches('-').to_string(),
                kv.get(1).cloned().unwrap_or_default(),
            )
        })
        .collect();
    let scene = Scene::build(&SceneDesc::load(scene_path.as_ref())?)?;
    let p = numbers(&args, "plane", 9)?;
    let v = |i: usize| DVec3::new(p[i], p[i + 1], p[i + 2]);
    let plane = LightPlane::new(v(0), v(3), v(6))?;
    let (center, size) = (numbers(&args, "center", 2)?, numbers(&args, "size", 2)?);
    let placement = Placement {
        center: [center[0], center[1]],
        size: [size[0], size[1]],
        intensity: number(&args, "intensity", 1.0)?,
    };
    let face = PlaneFace {
        order: number(&args, "order", 32.0)? as usize,
        side: number(&args, "side", 4.0)?,
    };
    let light = texture(args.get("texture").ok_or("--texture is required")?)?;
    let order2 = (face.order * face.order) as f64;
    let keep = ((number(&args, "source-share", 1.0)? * order2).ceil() as usize).max(1);
    let target = number(&args, "target-share", 1.0)?;
    let targets = if target < 1.0 {
        Targets::Share(target)
    } else {
        Targets::All
    };
    let source = SourceCoefficients::new(&light, &placement, face.order, keep)?;
    let out = args.get("o").ok_or("-o OUT.f32 is required")?;

    let t0 = Instant::now();
    let rows = bake_rows(&scene, &plane, face)?;
    let bake_s = t0.elapsed().as_secs_f64();
    let t1 = Instant::now();
    let image = relight(&rows, face, &source, &placement, targets);
    let relight_s = t1.elapsed().as_secs_f64();
    let bytes: Vec<u8> = image
        .iter()
        .flatten()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    std::fs::write(out, bytes)?;
    write_extras(&args, &rows, face, &placement)?;
    println!(
        "{} rows, order {}, {} source terms ({:.1} % of the light's energy), bake {bake_s:.2} s, relight {:.1} ms",
        rows.len(),
        face.order,
        source.terms(),
        100.0 * source.kept_energy(),
        relight_s * 1e3
    );
    Ok(())
}
