//! Renders a scene under a uniform white environment (L = 1 in every
//! texel), straight from its transport rows, as a binary PPM: a quick look
//! at framing, materials and shadows before a long bake.
//!
//! `cargo run --release -p ltm-bake --example preview -- SCENE.toml OUT.ppm [FACE_RES]`

use ltm_bake::{Overrides, Scene, SceneDesc};
use rayon::prelude::*;
use std::io::Write;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 3 {
        return Err("usage: preview SCENE.toml OUT.ppm [FACE_RES]".into());
    }
    let mut desc = SceneDesc::load(args[1].as_ref())?;
    let face_res = args.get(3).map(|s| s.parse()).transpose()?.unwrap_or(8);
    desc.apply(&Overrides {
        face_res: Some(face_res),
        ..Default::default()
    })?;
    let scene = Scene::build(&desc)?;
    let dims = scene.dims();
    let c = dims.channels as usize;
    let pixels: Vec<[f32; 3]> = (0..dims.pixels())
        .into_par_iter()
        .map(|p| {
            let mut row = vec![0.0f32; dims.row_len()];
            let mut albedo = [0.0f32; 3];
            scene.transport_row(p, &mut row, &mut albedo);
            let mut rgb = [0.0f32; 3];
            for j in 0..dims.lights() {
                for (ch, v) in rgb.iter_mut().enumerate() {
                    *v += row[j * c + ch.min(c - 1)];
                }
            }
            if c == 1 {
                for ch in 0..3 {
                    rgb[ch] *= albedo[ch];
                }
            }
            rgb
        })
        .collect();
    let mut out = std::io::BufWriter::new(std::fs::File::create(&args[2])?);
    write!(out, "P6\n{} {}\n255\n", dims.width(), dims.height())?;
    for px in pixels {
        for v in px {
            out.write_all(&[(v.clamp(0.0, 1.0).powf(1.0 / 2.2) * 255.0 + 0.5) as u8])?;
        }
    }
    Ok(())
}
