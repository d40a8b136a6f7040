//! The bands of a column image transformed to a depth, numbered once for
//! the codec (scale groups, band weights) and the relighter (its arena's
//! codes): band 0 is the low band, band `1 + 3·(k − 1) + o` orientation `o`
//! of the detail bands of level `k` (1 = finest; orientation 0 = right of
//! the level's low band, 1 = below, 2 = diagonal).

use crate::wavelet::band_size;
use std::ops::Range;

/// Bands of a column transformed to `depth`: the low band and three
/// orientations per level.
pub fn band_count(depth: u32) -> usize {
    3 * depth as usize + 1
}

/// The level of band `band`: 0 for the low band, `k` for the detail bands
/// of level `k` — the band's quantizer scale group.
pub fn band_level(band: usize) -> usize {
    if band == 0 {
        0
    } else {
        (band - 1) / 3 + 1
    }
}

/// The positions of band `band` (`< band_count(depth)`) of a `width` ×
/// `height` column image at `depth`: its columns and its rows (empty for a
/// band of an image too small to have it).
pub fn band_rect(
    width: usize,
    height: usize,
    depth: u32,
    band: usize,
) -> (Range<usize>, Range<usize>) {
    if band == 0 {
        let (lw, lh) = band_size(width, height, depth);
        return (0..lw, 0..lh);
    }
    let k = band_level(band) as u32;
    let (pw, ph) = band_size(width, height, k - 1);
    let (lw, lh) = band_size(width, height, k);
    match (band - 1) % 3 {
        0 => (lw..pw, 0..lh),
        1 => (0..lw, lh..ph),
        _ => (lw..pw, lh..ph),
    }
}

/// The band of every position of a `width` × `height` column image at
/// `depth`, row-major.
pub fn band_map(width: usize, height: usize, depth: u32) -> Vec<u8> {
    let mut map = vec![0u8; width * height];
    for band in 1..band_count(depth) {
        let (xs, ys) = band_rect(width, height, depth, band);
        for y in ys {
            map[y * width + xs.start..y * width + xs.end].fill(band as u8);
        }
    }
    map
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::wavelet::max_levels;

    /// The bands tile the image, and a position's band is the one whose
    /// rectangle holds it; levels follow the detail bands of each level.
    #[test]
    fn bands_tile_the_image() {
        for (w, h) in [(1, 1), (1, 7), (5, 3), (16, 16), (33, 17), (64, 40)] {
            for d in 0..=max_levels(w, h) {
                let mut count = vec![0u32; w * h];
                for b in 0..band_count(d) {
                    let (xs, ys) = band_rect(w, h, d, b);
                    for y in ys {
                        for x in xs.clone() {
                            count[y * w + x] += 1;
                        }
                    }
                }
                assert!(count.iter().all(|&c| c == 1), "{w}x{h} depth {d}");
                let map = band_map(w, h, d);
                for (i, &b) in map.iter().enumerate() {
                    let (xs, ys) = band_rect(w, h, d, b as usize);
                    assert!(xs.contains(&(i % w)) && ys.contains(&(i / w)));
                }
            }
        }
        assert_eq!(
            (0..7).map(band_level).collect::<Vec<_>>(),
            [0, 1, 1, 1, 2, 2, 2]
        );
    }
}
