//! The BVH: a binary tree built top-down with the binned surface area
//! heuristic (Wald 2007, "On fast Construction of SAH-based Bounding Volume
//! Hierarchies"), converted to obvhs's compressed wide BVH (Ylitie, Karras,
//! Laine 2017, "Efficient Incoherent Ray Traversal on GPUs Through
//! Compressed Wide BVHs") for traversal.
//!
//! Any input builds in O(n log n) time into a tree of bounded depth, however
//! degenerate (hundreds of coincident triangles, nested or exponentially
//! spaced ones): a node whose centroids all coincide, whose binned SAH finds
//! no split, or that lies [`SAH_DEPTH`] levels deep, is split at its median
//! (by centroid along the widest axis, ties by input order), which halves
//! it. The build uses an explicit stack, never recursion. If the wide BVH
//! is still deeper than obvhs's traversal allows, the tree is rebuilt with
//! median splits only (at most ⌈log₂ n⌉ levels).
//!
//! Conservative boxes: every triangle's box is grown by `pad` on each side,
//! so a ray that hits a triangle passes through the inside of every box on
//! its way by a margin far above the rounding of obvhs's ray/box test (and
//! of its box quantization); a ray along an edge shared by two triangles
//! cannot miss both of their boxes.

use crate::intersect::Tri;
use glam::Vec3A;
use obvhs::aabb::Aabb;
use obvhs::bvh2::node::Bvh2Node;
use obvhs::bvh2::Bvh2;
use obvhs::cwbvh::bvh2_to_cwbvh::bvh2_to_cwbvh;
use obvhs::cwbvh::CwBvh;

/// Depth below which nodes are split by the SAH; deeper ones at the median.
pub(crate) const SAH_DEPTH: u32 = 32;
/// Deepest wide BVH traced (obvhs traverses with a fixed 32-entry stack).
pub(crate) const MAX_DEPTH: u32 = 24;
/// SAH bins per split.
const BINS: usize = 32;

/// A primitive being sorted into the tree.
#[derive(Clone, Copy)]
struct Item {
    bounds: Aabb,
    centroid: Vec3A,
    index: u32,
}

/// The wide BVH over `tris` with boxes grown by `pad`, and its depth
/// (levels of nodes). Primitive ids in the BVH are positions in
/// `bvh.primitive_indices`, which maps them to indices into `tris`.
pub(crate) fn build(tris: &[Tri], pad: f32) -> (CwBvh, u32) {
    let items: Vec<Item> = tris
        .iter()
        .enumerate()
        .map(|(i, t)| {
            let b = Aabb::from_points(&t.vertices());
            let bounds = Aabb::new(b.min - pad, b.max + pad);
            Item {
                bounds,
                centroid: bounds.center(),
                index: i as u32,
            }
        })
        .collect();
    let bvh = convert(&binary(items.clone(), SAH_DEPTH));
    let depth = wide_depth(&bvh);
    if depth <= MAX_DEPTH {
        return (bvh, depth);
    }
    let bvh = convert(&binary(items, 0));
    let depth = wide_depth(&bvh);
    (bvh, depth)
}

fn convert(bvh2: &Bvh2) -> CwBvh {
    bvh2_to_cwbvh(bvh2, 3, true, false)
}

/// A binary tree, one primitive per leaf; nodes deeper than `sah_depth`
/// are split at the median.
fn binary(mut items: Vec<Item>, sah_depth: u32) -> Bvh2 {
    if items.is_empty() {
        return Bvh2::default();
    }
    let mut nodes = vec![Bvh2Node::default()];
    let mut stack = vec![(0usize, 0usize, items.len(), 0u32)];
    let mut max_depth = 0;
    while let Some((node, start, end, depth)) = stack.pop() {
        max_depth = max_depth.max(depth as usize + 1);
        let range = &mut items[start..end];
        let bounds = range
            .iter()
            .fold(Aabb::empty(), |b, it| b.union(&it.bounds));
        if range.len() == 1 {
            nodes[node] = Bvh2Node::new(bounds, 1, start as u32);
            continue;
        }
        let mid = start + split(range, depth < sah_depth);
        let left = nodes.len();
        nodes.extend([Bvh2Node::default(); 2]);
        nodes[node] = Bvh2Node::new(bounds, 0, left as u32);
        stack.push((left, start, mid, depth + 1));
        stack.push((left + 1, mid, end, depth + 1));
    }
    Bvh2 {
        nodes,
        primitive_indices: items.iter().map(|it| it.index).collect(),
        max_depth,
        ..Default::default()
    }
}

/// Reorders `items` (at least 2) into two non-empty halves and returns the
/// size of the first: the best binned-SAH split when `sah`, else (or when
/// no SAH split exists) the median.
fn split(items: &mut [Item], sah: bool) -> usize {
    let (lo, hi) = items.iter().fold(
        (Vec3A::splat(f32::INFINITY), Vec3A::splat(f32::NEG_INFINITY)),
        |(lo, hi), it| (lo.min(it.centroid), hi.max(it.centroid)),
    );
    let extent = hi - lo;
    let axis = if extent.x >= extent.y && extent.x >= extent.z {
        0
    } else if extent.y >= extent.z {
        1
    } else {
        2
    };
    if sah {
        let mut best: Option<(f32, usize, usize)> = None;
        for ax in 0..3 {
            if extent[ax] <= 0.0 {
                continue;
            }
            let scale = BINS as f32 / extent[ax];
            let bin = |it: &Item| (((it.centroid[ax] - lo[ax]) * scale) as usize).min(BINS - 1);
            if let Some((cost, cut)) = best_bin_split(items, &bin) {
                if best.is_none_or(|(c, _, _)| cost < c) {
                    best = Some((cost, cut, ax));
                }
            }
        }
        if let Some((_, cut, ax)) = best {
            let scale = BINS as f32 / extent[ax];
            let bin = |it: &Item| (((it.centroid[ax] - lo[ax]) * scale) as usize).min(BINS - 1);
            let mid = partition(items, |it| bin(it) < cut);
            if mid > 0 && mid < items.len() {
                return mid;
            }
        }
    }
    let mid = items.len() / 2;
    items.select_nth_unstable_by(mid, |a, b| {
        a.centroid[axis]
            .total_cmp(&b.centroid[axis])
            .then(a.index.cmp(&b.index))
    });
    mid
}

/// The bin boundary (items in bins below it go left) of least SAH cost
/// `area(L)·|L| + area(R)·|R|`, if any leaves both sides non-empty.
fn best_bin_split(items: &[Item], bin: &dyn Fn(&Item) -> usize) -> Option<(f32, usize)> {
    let mut count = [0usize; BINS];
    let mut boxes = [Aabb::empty(); BINS];
    for it in items {
        let b = bin(it);
        count[b] += 1;
        boxes[b] = boxes[b].union(&it.bounds);
    }
    // Right-to-left sweep: cost of the right side of each boundary.
    let mut right = [0f32; BINS];
    let (mut acc, mut n) = (Aabb::empty(), 0);
    for b in (1..BINS).rev() {
        acc = acc.union(&boxes[b]);
        n += count[b];
        right[b] = if n == 0 {
            f32::INFINITY
        } else {
            acc.half_area() * n as f32
        };
    }
    let (mut acc, mut n) = (Aabb::empty(), 0);
    let mut best: Option<(f32, usize)> = None;
    for cut in 1..BINS {
        acc = acc.union(&boxes[cut - 1]);
        n += count[cut - 1];
        if n == 0 || n == items.len() {
            continue;
        }
        let cost = acc.half_area() * n as f32 + right[cut];
        if best.is_none_or(|(c, _)| cost < c) {
            best = Some((cost, cut));
        }
    }
    best
}

/// Moves the items satisfying `left` to the front; returns their count.
fn partition(items: &mut [Item], left: impl Fn(&Item) -> bool) -> usize {
    let mut mid = 0;
    for i in 0..items.len() {
        if left(&items[i]) {
            items.swap(i, mid);
            mid += 1;
        }
    }
    mid
}

/// Depth of a wide BVH (1 for a root-only tree), without recursion.
fn wide_depth(bvh: &CwBvh) -> u32 {
    if bvh.nodes.is_empty() {
        return 0;
    }
    let mut max = 0;
    let mut stack = vec![(0usize, 1u32)];
    while let Some((i, d)) = stack.pop() {
        max = max.max(d);
        let Some(node) = bvh.nodes.get(i) else {
            continue;
        };
        for c in 0..node.imask.count_ones() as usize {
            stack.push((node.child_base_idx as usize + c, d + 1));
        }
    }
    max
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tri(x: f32, y: f32, s: f32) -> Tri {
        Tri::new([
            Vec3A::new(x, y, 0.0),
            Vec3A::new(x + s, y, 0.0),
            Vec3A::new(x, y + s, 0.1),
        ])
    }

    /// Degenerate distributions give shallow trees that hold every
    /// primitive once.
    #[test]
    fn degenerate_inputs_build_shallow_trees() {
        let cases: Vec<(&str, Vec<Tri>)> = vec![
            ("coincident", vec![tri(0.0, 0.0, 1.0); 5000]),
            (
                "nested",
                (0..5000)
                    .map(|i| tri(-(i as f32), -(i as f32), 1.0 + 2.0 * i as f32))
                    .collect(),
            ),
            (
                "exponential",
                (0..120)
                    .map(|i| tri(2f32.powi(-i / 2), 0.0, 1e-3))
                    .collect(),
            ),
            ("one", vec![tri(0.0, 0.0, 1.0)]),
        ];
        for (name, tris) in cases {
            let (bvh, depth) = build(&tris, 1e-3);
            assert!(depth <= MAX_DEPTH, "{name}: depth {depth}");
            let mut seen: Vec<u32> = bvh.primitive_indices.clone();
            seen.sort_unstable();
            assert_eq!(seen, (0..tris.len() as u32).collect::<Vec<_>>(), "{name}");
        }
    }
}
