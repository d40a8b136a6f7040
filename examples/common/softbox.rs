//! What the near-field examples share: the Mitsuba check's softbox light
//! (`tools/validate/mitsuba_nearfield.py`), the paper's 1 % / 20 % terms,
//! a frame timer and the images' relative L2.

use ltm::relight::nearfield::{
    AreaLight, LightTexture, NearField, NearFieldMethod, NearFieldTerms, Placement, Targets,
};
use std::error::Error;
use std::time::Instant;

pub type Outcome<T> = Result<T, Box<dyn Error>>;

/// The wavelet method at 1 % source and 20 % target terms (the paper's
/// real-time setting).
pub const WAVELET_1_20: NearFieldMethod = NearFieldMethod::Wavelet(NearFieldTerms {
    source: 0.01,
    targets: Targets::Share(0.2),
});

/// The softbox at 0.8 × 0.6 centred at (0.15, 0.25), intensity 4.
pub fn softbox_light() -> Outcome<AreaLight> {
    Ok(AreaLight {
        texture: softbox()?,
        placement: Placement {
            center: [0.15, 0.25],
            size: [0.8, 0.6],
            intensity: 4.0,
        },
    })
}

/// The 64 × 48 RGB texture: a warm left half and a cool right one, dark
/// stripes across the middle and a bright disc near a corner.
pub fn softbox() -> Outcome<LightTexture> {
    let (w, h) = (64usize, 48usize);
    let mut texels = Vec::with_capacity(w * h);
    for y in 0..h {
        for x in 0..w {
            let (u, v) = ((x as f32 + 0.5) / w as f32, (y as f32 + 0.5) / h as f32);
            let left = u < 0.5;
            let mut t = [
                if left { 1.6 } else { 0.5 },
                0.9,
                if left { 0.4 } else { 1.5 },
            ];
            if ((v * 6.0).floor() as i32) % 2 == 1 && u > 0.2 && u < 0.8 {
                t.iter_mut().for_each(|c| *c *= 0.15);
            }
            if (u - 0.8).powi(2) + (v - 0.2).powi(2) < 0.01 {
                t = [6.0, 6.0, 5.0];
            }
            texels.push(t);
        }
    }
    Ok(LightTexture::new(w, h, texels)?)
}

/// Median frame time in ms of `frames` renders (at least one), and the
/// last image.
pub fn time(
    near: &NearField,
    light: &AreaLight,
    method: NearFieldMethod,
    frames: usize,
) -> Outcome<(f64, Vec<[f32; 3]>)> {
    let frames = frames.max(1);
    let mut times = Vec::with_capacity(frames);
    let mut image = Vec::new();
    for _ in 0..frames {
        let start = Instant::now();
        image = near.render(std::slice::from_ref(light), method)?;
        times.push(start.elapsed().as_secs_f64() * 1e3);
    }
    times.sort_by(f64::total_cmp);
    Ok((times[frames / 2], image))
}

/// `‖a − b‖ / ‖b‖` over every channel.
pub fn relative_l2(a: &[[f32; 3]], b: &[[f32; 3]]) -> f64 {
    let (mut e, mut n) = (0.0f64, 0.0f64);
    for (x, y) in a.iter().flatten().zip(b.iter().flatten()) {
        e += (f64::from(*x) - f64::from(*y)).powi(2);
        n += f64::from(*y).powi(2);
    }
    (e / n.max(f64::MIN_POSITIVE)).sqrt()
}
