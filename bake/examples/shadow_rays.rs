//! The shadow rays of a bake, traced by ltm's tracer, and written for
//! another tracer to trace the same rays: `tools/validate/embree_rays.py`
//! traces them with Embree (Mitsuba 3's `ray_test`) and compares the
//! answers and the rays per second.
//!
//! `cargo run --release -p ltm-bake --example shadow_rays -- SCENE.toml WIDTH HEIGHT FACE_RES MAX_RAYS OUT_DIR`
//!
//! Rows are taken evenly spaced until about MAX_RAYS rays; each row's rays
//! are exactly those `ltm bake` traces for it, in its order and in its
//! packets. Writes to OUT_DIR: `rays.f32` (origin xyz, direction xyz per
//! ray, little-endian f32, world units), `occluded.u8` (ltm's answer per
//! ray), `world.f32` (the traced triangles, nine f32 each). Prints one JSON
//! line: the ray and triangle counts, and ltm's rays/s replaying the rays
//! on one thread and on all threads (median of 5 runs each), as the bake
//! traces them (`Scene::occluded_packet`, packet by packet) and one at a
//! time (`Scene::occluded`). It fails if the two ways disagree on a ray.

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
    let packets = collect(&scene, max_rays);
    let rays: Vec<(DVec3, DVec3, bool)> = packets
        .iter()
        .flat_map(|p| p.dirs.iter().zip(&p.hits).map(|(&d, &h)| (p.origin, d, h)))
        .collect();
    if let Some(i) = rays.iter().position(|&(o, d, h)| scene.occluded(o, d) != h) {
        return Err(format!("ray {i}: the packet and the single ray disagree").into());
    }
    let one = median_rate(rays.len(), |_| replay_single(&rays, &scene, false));
    let all = median_rate(rays.len(), |_| replay_single(&rays, &scene, true));
    let packet_one = median_rate(rays.len(), |_| replay_packets(&packets, &scene, false));
    let packet_all = median_rate(rays.len(), |_| replay_packets(&packets, &scene, true));
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
        "{{\"rays\": {}, \"packets\": {}, \"triangles\": {}, \"threads\": {}, \"ltm_rays_per_s_one_thread\": {packet_one:.0}, \"ltm_rays_per_s_all_threads\": {packet_all:.0}, \"single_rays_per_s_one_thread\": {one:.0}, \"single_rays_per_s_all_threads\": {all:.0}}}",
        rays.len(),
        packets.len(),
        tris.len(),
        rayon::current_num_threads()
    );
    Ok(())
}

/// One packet of the bake: rays from one origin and ltm's answers.
struct Packet {
    origin: DVec3,
    dirs: Vec<DVec3>,
    hits: Vec<bool>,
}

/// The bake's shadow rays of rows taken evenly spaced until about
/// `max_rays` rays, in its packets, with ltm's answers.
fn collect(scene: &Scene, max_rays: usize) -> Vec<Packet> {
    let pixels = scene.dims().pixels();
    let mut per_row = 0;
    scene.shadow_rays(pixels / 2, &mut |_, d, _| per_row += d.len());
    let step = (pixels * per_row.max(1) / max_rays.max(1)).max(1);
    let rows: Vec<usize> = (0..pixels).step_by(step).collect();
    rows.par_iter()
        .map(|&p| {
            let mut packets = Vec::new();
            scene.shadow_rays(p, &mut |origin, dirs, hits| {
                packets.push(Packet {
                    origin,
                    dirs: dirs.to_vec(),
                    hits: hits.to_vec(),
                })
            });
            packets
        })
        .flatten()
        .collect()
}

/// Replays `rays` one at a time; returns the count occluded.
fn replay_single(rays: &[(DVec3, DVec3, bool)], scene: &Scene, parallel: bool) -> usize {
    if parallel {
        rays.par_iter()
            .filter(|(o, d, _)| scene.occluded(*o, *d))
            .count()
    } else {
        rays.iter()
            .filter(|(o, d, _)| scene.occluded(*o, *d))
            .count()
    }
}

/// Replays `packets` as the bake traces them; returns the count occluded.
fn replay_packets(packets: &[Packet], scene: &Scene, parallel: bool) -> usize {
    let one = |p: &Packet| {
        let mut out = vec![false; p.dirs.len()];
        scene.occluded_packet(p.origin, &p.dirs, &mut out);
        out.iter().filter(|&&h| h).count()
    };
    if parallel {
        packets.par_iter().map(one).sum()
    } else {
        packets.iter().map(one).sum()
    }
}

/// Rays per second of `run` over `rays` rays, median of 5 runs.
fn median_rate(rays: usize, run: impl Fn(()) -> usize) -> f64 {
    let mut rates: Vec<f64> = (0..5)
        .map(|_| {
            let start = Instant::now();
            std::hint::black_box(run(()));
            rays as f64 / start.elapsed().as_secs_f64()
        })
        .collect();
    rates.sort_by(f64::total_cmp);
    rates[2]
}
