//! The shadow rays of a bake, traced by ltm's tracer, and written for
//! another tracer to trace the same rays: `tools/validate/embree_rays.py`
//! traces them with Embree (Mitsuba 3's `ray_test`) and compares the
//! answers and the rays per second.
//!
//! `cargo run --release -p ltm-bake --example shadow_rays -- SCENE.toml WIDTH HEIGHT FACE_RES MAX_RAYS OUT_DIR`
//!
//! Rows are taken evenly spaced until about MAX_RAYS rays; each row's rays
//! are exactly those `ltm bake` traces for it, in its order. Writes to
//! OUT_DIR: `rays.f32` (origin xyz, direction xyz per ray, little-endian
//! f32, world units), `occluded.u8` (ltm's answer per ray), `world.f32`
//! (the traced triangles, nine f32 each). Prints one JSON line: the ray
//! and triangle counts, and ltm's rays/s replaying the rays on one thread
//! and on all threads (median of 5 runs each).

use glam::DVec3;
use ltm_bake::{Overrides, Scene, SceneDesc};
use rayon::prelude::*;
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() != 7 {
        return Err("usage: shadow_rays SCENE.toml WIDTH HEIGHT FACE_RES MAX_RAYS OUT_DIR".into());
    }
    let number = |i: usize| args[i].parse::<u32>();
    let mut desc = SceneDesc::load(args[1].as_ref())?;
    desc.apply(&Overrides {
        width: Some(number(2)?),
        height: Some(number(3)?),
        face_res: Some(number(4)?),
        ..Default::default()
    })?;
    let max_rays: usize = args[5].parse()?;
    let out = std::path::Path::new(&args[6]);
    std::fs::create_dir_all(out)?;
    let scene = Scene::build(&desc)?;
    let rays = collect(&scene, max_rays);
    let one = median_rate(&rays, &scene, false);
    let all = median_rate(&rays, &scene, true);
    let flat: Vec<f32> = rays
        .iter()
        .flat_map(|(o, d, _)| [o.x, o.y, o.z, d.x, d.y, d.z].map(|v| v as f32))
        .collect();
    std::fs::write(out.join("rays.f32"), bytemuck::cast_slice(&flat))?;
    let hits: Vec<u8> = rays.iter().map(|r| r.2 as u8).collect();
    std::fs::write(out.join("occluded.u8"), &hits)?;
    let tris = scene.world_triangles();
    std::fs::write(out.join("world.f32"), bytemuck::cast_slice(&tris))?;
    println!(
        "{{\"rays\": {}, \"triangles\": {}, \"threads\": {}, \"ltm_rays_per_s_one_thread\": {one:.0}, \"ltm_rays_per_s_all_threads\": {all:.0}}}",
        rays.len(),
        tris.len(),
        rayon::current_num_threads()
    );
    Ok(())
}

/// The bake's shadow rays of rows taken evenly spaced until about
/// `max_rays` rays, with ltm's answers.
fn collect(scene: &Scene, max_rays: usize) -> Vec<(DVec3, DVec3, bool)> {
    let pixels = scene.dims().pixels();
    let mut first = Vec::new();
    scene.shadow_rays(pixels / 2, &mut |o, d, hit| first.push((o, d, hit)));
    let per_row = first.len().max(1);
    let step = (pixels * per_row / max_rays.max(1)).max(1);
    let rows: Vec<usize> = (0..pixels).step_by(step).collect();
    rows.par_iter()
        .map(|&p| {
            let mut rays = Vec::new();
            scene.shadow_rays(p, &mut |o, d, hit| rays.push((o, d, hit)));
            rays
        })
        .flatten()
        .collect()
}

/// ltm's shadow rays per second over `rays`, median of 5 runs, on one
/// thread or on all of rayon's.
fn median_rate(rays: &[(DVec3, DVec3, bool)], scene: &Scene, parallel: bool) -> f64 {
    let mut rates: Vec<f64> = (0..5)
        .map(|_| {
            let start = Instant::now();
            let hits = if parallel {
                rays.par_iter()
                    .filter(|(o, d, _)| scene.occluded(*o, *d))
                    .count()
            } else {
                rays.iter()
                    .filter(|(o, d, _)| scene.occluded(*o, *d))
                    .count()
            };
            std::hint::black_box(hits);
            rays.len() as f64 / start.elapsed().as_secs_f64()
        })
        .collect();
    rates.sort_by(f64::total_cmp);
    rates[2]
}
