//! The 1D affine coupling coefficients (ACCs) of the orthonormal Haar basis
//! on `[0, 1)`: `D_ik(s, o) = ∫₀¹ Φ_i(s·w + o)·Φ_k(w) dw` (eq. 8), exact.
//!
//! Index 0 is the scaling function `φ = 1` on `[0, 1)`; index `i ≥ 1` is the
//! wavelet of level `l = ⌊log₂ i⌋` and offset `t = i − 2^l`,
//! `2^{l/2}·ψ(2^l·w − t)` with `ψ` = +1 on its first half and −1 on its
//! second. This is the codec's 1D Haar ([`ltm_codec::wavelet::forward_1d`]
//! with [`ltm_codec::Filter::Haar`], Mallat layout) read as a basis.
//!
//! Every basis function is at most two constant pieces, so one coefficient is
//! a sum of at most four interval overlaps: the closed form of the paper's
//! canonical coupling coefficient `M(r, c)` (eq. 16–17), without its table.
//! [`couplings`] lists the nonzero `k` of one source function `i`: a target
//! wavelet is nonzero only where its support holds a break of the
//! transformed source (otherwise the source is constant over it and the
//! wavelet integrates to zero), so each level has at most three, and a
//! source couples to `O(log N)` targets (§4.2.4, Appendix D).

/// A constant piece `[start, end)` with its value.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Piece {
    pub start: f64,
    pub end: f64,
    pub value: f64,
}

/// The pieces of basis function `i` on `[0, 1)` (`i < n` for order `n`;
/// any `i` is defined, the order only bounds the levels used).
pub(super) fn pieces(i: usize) -> ([Piece; 2], usize) {
    if i == 0 {
        let whole = Piece {
            start: 0.0,
            end: 1.0,
            value: 1.0,
        };
        return ([whole, whole], 1);
    }
    let level = usize::BITS - 1 - i.leading_zeros();
    let offset = (i - (1usize << level)) as f64;
    let width = 1.0 / (1u64 << level) as f64;
    // 2^{level/2}, without a square root.
    let amplitude = (1u64 << (level / 2)) as f64
        * if level % 2 == 1 {
            std::f64::consts::SQRT_2
        } else {
            1.0
        };
    let start = offset * width;
    let middle = start + 0.5 * width;
    let piece = |start, end, value| Piece { start, end, value };
    (
        [
            piece(start, middle, amplitude),
            piece(middle, start + width, -amplitude),
        ],
        2,
    )
}

/// The pieces of `w ↦ Φ_i(s·w + o)`: each source piece `[a, b)` becomes
/// `[(a − o)/s, (b − o)/s)` (`s > 0`).
fn transformed(i: usize, s: f64, o: f64) -> ([Piece; 2], usize) {
    let (mut p, count) = pieces(i);
    for piece in &mut p[..count] {
        piece.start = (piece.start - o) / s;
        piece.end = (piece.end - o) / s;
    }
    (p, count)
}

/// `Σ value_a·value_b·|a ∩ b|` over the pieces of two functions.
fn overlap(a: &[Piece], b: &[Piece]) -> f64 {
    let mut sum = 0.0;
    for x in a {
        for y in b {
            let length = x.end.min(y.end) - x.start.max(y.start);
            if length > 0.0 {
                sum += x.value * y.value * length;
            }
        }
    }
    sum
}

/// The exact coefficient `D_ik(s, o)` for `s > 0` and finite `o`.
pub fn coupling(i: usize, k: usize, s: f64, o: f64) -> f64 {
    let (source, m) = transformed(i, s, o);
    let (target, n) = pieces(k);
    overlap(&source[..m], &target[..n])
}

/// Appends to `out` every `(k, D_ik(s, o))` with `k < order` and a nonzero
/// coefficient, in increasing `k`. `order` is a power of two, `s > 0` and
/// `o` finite (the caller checks).
pub fn couplings(i: usize, order: usize, s: f64, o: f64, out: &mut Vec<(u32, f64)>) {
    let (source, m) = transformed(i, s, o);
    let source = &source[..m];
    let mut push = |k: usize| {
        let (target, n) = pieces(k);
        let d = overlap(source, &target[..n]);
        if d != 0.0 {
            out.push((k as u32, d));
        }
    };
    push(0);
    // The breaks of the transformed source inside [0, 1).
    let mut breaks = [0.0f64; 3];
    let mut count = 0;
    for e in source
        .iter()
        .map(|p| p.start)
        .chain(std::iter::once(source[m - 1].end))
    {
        if (0.0..1.0).contains(&e) {
            breaks[count] = e;
            count += 1;
        }
    }
    let levels = order.trailing_zeros();
    for level in 0..levels {
        let base = 1usize << level;
        let mut last = usize::MAX;
        // Breaks are increasing, so equal offsets are adjacent.
        for &e in &breaks[..count] {
            let t = ((e * base as f64) as usize).min(base - 1);
            if t != last {
                push(base + t);
                last = t;
            }
        }
    }
}
