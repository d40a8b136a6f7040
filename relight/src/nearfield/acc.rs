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
///
/// The transformed source is a sum of steps: its value `v₀` at `w = 0` and
/// a jump `j` at each break `b ∈ (0, 1)`. A step from `b` couples to
/// target `k` by its tail integral `E_k(b) = ∫_b^1 Φ_k`, which is `1 − b`
/// for the scaling function and, for a wavelet of support `[x₀, x₁)` that
/// holds `b`, the hat `−2^{l/2}·min(b − x₀, x₁ − b)` (zero outside its
/// support: a wavelet integrates to zero). So
/// `D_ik = v₀·δ_k0 + Σ_b j·E_k(b)`: one target per level and break.
pub fn couplings(i: usize, order: usize, s: f64, o: f64, out: &mut Vec<(u32, f64)>) {
    couplings_where(i, order, s, o, |_| true, out);
}

/// [`couplings`] for the targets `k` where `wanted(k)` holds only (the
/// others are not evaluated).
pub fn couplings_where(
    i: usize,
    order: usize,
    s: f64,
    o: f64,
    wanted: impl Fn(usize) -> bool,
    out: &mut Vec<(u32, f64)>,
) {
    if s > 2.0 * order as f64 {
        // The source is narrower than half a finest texel: steps from
        // nearby breaks would cancel to rounding, overlaps do not.
        let (source, m) = transformed(i, s, o);
        return couplings_by_overlap(&source[..m], order, wanted, out);
    }
    let (value, steps, count) = steps(i, s, o);
    let steps = &steps[..count];
    let d0 = value + steps.iter().map(|&(b, j)| j * (1.0 - b)).sum::<f64>();
    if d0 != 0.0 && wanted(0) {
        out.push((0, d0));
    }
    let levels = order.trailing_zeros() as usize;
    // Each break's texel at the finest level; a coarser level's texel is
    // that index shifted right.
    let mut finest = [0usize; 3];
    for (f, &(b, _)) in finest.iter_mut().zip(steps) {
        *f = ((b * order as f64) as usize).min(order - 1);
    }
    for level in 0..levels {
        let amplitude = amplitude(level);
        let base = 1usize << level;
        let width = inverse_power_of_two(level);
        let shift = levels - level;
        // Breaks are increasing, so equal offsets are adjacent: their
        // steps add up in `sum` before the entry is written.
        let (mut last, mut sum) = (usize::MAX, 0.0);
        for (&(b, j), &f) in steps.iter().zip(&finest) {
            let t = f >> shift;
            let x0 = t as f64 * width;
            let (left, right) = (b - x0, x0 + width - b);
            let e = -amplitude * if left < right { left } else { right } * j;
            if t == last {
                sum += e;
                continue;
            }
            push_nonzero(last, base, sum, &wanted, out);
            (last, sum) = (t, e);
        }
        push_nonzero(last, base, sum, &wanted, out);
    }
}

/// Appends target `base + t` with coupling `d`, unless `t` is none
/// (`usize::MAX`), `d` is 0 (the steps cancel, or a break is on an edge) or
/// the target is not wanted.
#[inline(always)]
fn push_nonzero(
    t: usize,
    base: usize,
    d: f64,
    wanted: &impl Fn(usize) -> bool,
    out: &mut Vec<(u32, f64)>,
) {
    if t != usize::MAX && d != 0.0 && wanted(base + t) {
        out.push(((base + t) as u32, d));
    }
}

/// `2^{l/2}`: a wavelet's value on level `l`.
pub(super) fn amplitude(level: usize) -> f64 {
    AMPLITUDES
        .get(level)
        .copied()
        .unwrap_or_else(|| (0.5 * level as f64).exp2())
}

/// `2^{−l}`, exact, without a division (`l` below 1023).
pub(super) fn inverse_power_of_two(level: usize) -> f64 {
    f64::from_bits((1023 - level as u64) << 52)
}

/// `2^{l/2}` for the levels of an order up to 2^20, exact.
const AMPLITUDES: [f64; 20] = {
    let mut a = [0.0; 20];
    let mut l = 0;
    while l < 20 {
        let even = (1u64 << (l / 2)) as f64;
        a[l] = if l % 2 == 1 {
            even * std::f64::consts::SQRT_2
        } else {
            even
        };
        l += 1;
    }
    a
};

/// The transformed source `w ↦ Φ_i(s·w + o)` as steps: its value at
/// `w = 0` and the `(break, jump)` pairs inside `(0, 1)`, increasing.
fn steps(i: usize, s: f64, o: f64) -> (f64, [(f64, f64); 3], usize) {
    let (breaks, jumps, n) = if i == 0 {
        ([0.0, 1.0, 0.0], [1.0, -1.0, 0.0], 2)
    } else {
        let level = (usize::BITS - 1 - i.leading_zeros()) as usize;
        let width = inverse_power_of_two(level);
        let start = (i - (1usize << level)) as f64 * width;
        let a = amplitude(level);
        (
            [start, start + 0.5 * width, start + width],
            [a, -2.0 * a, a],
            3,
        )
    };
    let inverse = 1.0 / s;
    let mut value = 0.0;
    let mut out = [(0.0, 0.0); 3];
    let mut count = 0;
    for (&x, &jump) in breaks.iter().zip(&jumps).take(n) {
        let b = (x - o) * inverse;
        if b <= 0.0 {
            value += jump;
        } else if b < 1.0 {
            out[count] = (b, jump);
            count += 1;
        }
    }
    (value, out, count)
}

/// [`couplings_where`] from the overlaps of the transformed source's
/// pieces with each candidate target's (a target per level and break).
fn couplings_by_overlap(
    source: &[Piece],
    order: usize,
    wanted: impl Fn(usize) -> bool,
    out: &mut Vec<(u32, f64)>,
) {
    let mut push = |k: usize| {
        if !wanted(k) {
            return;
        }
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
        .chain(std::iter::once(source[source.len() - 1].end))
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
