//! The page's map preview: a small lat-long copy of each map (box-filtered
//! once, at start), drawn rotated as the relighter sees it, so that the
//! preview shows what `yaw`, `pitch` and `roll` do to the lighting.

use ltm_codec::cubemap::{latlong_direction, latlong_uv};
use ltm_relight::{EnvMap, Image, Rotation};

/// Width of a preview (its height is half); a smaller map keeps its size.
pub const PREVIEW_WIDTH: usize = 256;

/// A map's preview, unrotated.
pub struct Preview {
    width: usize,
    height: usize,
    data: Vec<[f32; 3]>,
}

impl Preview {
    /// The box-filtered copy of `env` at most [`PREVIEW_WIDTH`] wide: each
    /// preview pixel is the mean of the map's pixels whose centres fall in
    /// it (lat-long maps are 2:1, so the factor is the same both ways).
    pub fn new(env: &EnvMap) -> Preview {
        let (w, h) = (env.width(), env.height());
        let width = w.min(PREVIEW_WIDTH);
        let height = (width / 2).max(1);
        let mut sum = vec![[0f64; 3]; width * height];
        let mut count = vec![0u32; width * height];
        for (i, p) in env.data().iter().enumerate() {
            let (x, y) = (i % w, i / w);
            let k = (y * height / h) * width + x * width / w;
            for c in 0..3 {
                sum[k][c] += f64::from(p[c]);
            }
            count[k] += 1;
        }
        let data = sum
            .iter()
            .zip(&count)
            .map(|(s, &n)| s.map(|v| (v / f64::from(n.max(1))) as f32))
            .collect();
        Preview {
            width,
            height,
            data,
        }
    }

    /// The preview under `rotation`: pixel ω shows the map's light from
    /// `R⁻¹·ω` (nearest pixel), as [`Rotation`] defines the rotated
    /// lighting.
    pub fn rotated(&self, rotation: &Rotation) -> Image {
        let inverse = rotation.matrix().transpose();
        let (w, h) = (self.width, self.height);
        let mut image = Image::new(w, h);
        for y in 0..h {
            for x in 0..w {
                let d = latlong_direction((x as f64 + 0.5) / w as f64, (y as f64 + 0.5) / h as f64);
                let (u, v) = latlong_uv(inverse * d);
                let sx = ((u * w as f64) as usize).min(w - 1);
                let sy = ((v * h as f64) as usize).min(h - 1);
                image.data[y * w + x] = self.data[sy * w + sx];
            }
        }
        image
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A map bright in one pixel column band: the preview keeps its mean,
    /// and a yaw moves the band by the yaw's share of the width (towards
    /// smaller u for a positive yaw, as `Rotation` turns directions).
    #[test]
    fn previews_average_and_rotate() {
        let env = EnvMap::from_fn(
            512,
            256,
            |x, _| if x / 64 == 2 { [1.0; 3] } else { [0.0; 3] },
        )
        .unwrap();
        let p = Preview::new(&env);
        assert_eq!((p.width, p.height), (256, 128));
        let lit = |img: &Image| -> Vec<usize> {
            (0..img.width)
                .filter(|&x| img.data[64 * img.width + x][0] > 0.5)
                .collect()
        };
        let still = p.rotated(&Rotation::IDENTITY);
        assert_eq!(lit(&still), (64..96).collect::<Vec<_>>());
        let turned = p.rotated(&Rotation::yaw(45.0));
        assert_eq!(lit(&turned), (32..64).collect::<Vec<_>>());
        let small = EnvMap::constant(64, 32, [2.0; 3]).unwrap();
        let q = Preview::new(&small).rotated(&Rotation::new(10.0, 20.0, 30.0));
        assert_eq!((q.width, q.height), (64, 32));
        assert!(q.data.iter().all(|v| *v == [2.0; 3]));
    }
}
