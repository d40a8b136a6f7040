//! Shadow rays traced as packets: up to [`PACKET`] rays walk obvhs's
//! compressed wide BVH together (masked packet traversal, Wald, Slusallek,
//! Benthin and Wagner 2001, "Interactive Rendering with Coherent Ray
//! Tracing"). Each node is fetched and its eight quantized child boxes are
//! expanded to `f32` once for the whole packet; each ray then tests them
//! with exactly the arithmetic of obvhs's single-ray test
//! (`CwBvhNode::intersect_ray_simd`: the same products and sums, not fused,
//! the same `max`/`min` order and NaN behaviour, the same `1e-4` floor on
//! the entry distance). A stack entry carries the mask of the rays whose
//! own test reached it, and a leaf's triangles are tested only for those
//! rays, so every ray tests exactly the boxes and triangles its own
//! traversal would reach: the answers are the single-ray answers, bit for
//! bit (tested against [`crate::Scene::occluded`]).
//!
//! The bake's rays suit this: all rays of a row's sample start at one
//! point, and those of neighbouring cubemap texels point within a few
//! degrees of each other, so they cross nearly the same nodes.

use crate::intersect::{Tri, WtRay};
use glam::{Vec3A, Vec4};
use obvhs::cwbvh::node::CwBvhNode;
use obvhs::cwbvh::CwBvh;
use obvhs::ray::safe_inverse;

/// Most rays a packet holds (one bit each of a `u64`).
pub(crate) const PACKET: usize = 64;
/// obvhs's floor on a box's entry distance.
const EPSILON: f32 = 0.0001;

/// One ray of a packet: obvhs's form (origin, inverse direction from
/// `obvhs::ray::safe_inverse`, which octant) and the watertight test's.
#[derive(Clone, Copy, Debug)]
pub(crate) struct PacketRay {
    org: [f32; 3],
    inv: [f32; 3],
    negative: [bool; 3],
    wt: WtRay,
    /// The farthest hit that counts, in trace-space distance.
    tmax: f32,
}

/// A packet being filled: up to [`PACKET`] rays and the caller's index of
/// each.
#[derive(Default)]
pub(crate) struct Packet {
    rays: Vec<PacketRay>,
    index: Vec<u32>,
    /// The traversal stack: node index and the rays that reached it.
    stack: Vec<(u32, u64)>,
}

impl Packet {
    /// Empties the packet.
    pub(crate) fn clear(&mut self) {
        self.rays.clear();
        self.index.clear();
    }

    /// Adds the ray from `org` along `dir` (of any non-zero length), to be
    /// reported as the caller's `index`.
    pub(crate) fn push(&mut self, index: usize, org: Vec3A, dir: Vec3A) {
        self.push_until(index, org, dir, f32::INFINITY);
    }

    /// [`Packet::push`] for a ray whose hits count only up to `tmax` (a
    /// trace-space distance along a unit `dir`).
    pub(crate) fn push_until(&mut self, index: usize, org: Vec3A, dir: Vec3A, tmax: f32) {
        debug_assert!(self.rays.len() < PACKET);
        let inv = [dir.x, dir.y, dir.z].map(safe_inverse);
        self.rays.push(PacketRay {
            org: org.to_array(),
            inv,
            negative: [dir.x < 0.0, dir.y < 0.0, dir.z < 0.0],
            wt: WtRay::new(org, dir),
            tmax,
        });
        self.index.push(index as u32);
    }

    /// The caller's index of each ray, in order.
    pub(crate) fn index(&self) -> &[u32] {
        &self.index
    }

    /// Which rays are occluded: bit `k` for the `k`-th ray pushed.
    pub(crate) fn trace(&mut self, bvh: &CwBvh, tris: &[Tri]) -> u64 {
        occluded(bvh, tris, &self.rays, &mut self.stack)
    }
}

/// A node's eight child boxes in its quantized grid units, as `f32`, four
/// children to a vector: `lo[axis][half]`, `hi[axis][half]`.
struct Children {
    lo: [[Vec4; 2]; 3],
    hi: [[Vec4; 2]; 3],
}

impl Children {
    fn of(node: &CwBvhNode) -> Children {
        let f = |q: &[u8; 8]| {
            let q = q.map(f32::from);
            [
                Vec4::new(q[0], q[1], q[2], q[3]),
                Vec4::new(q[4], q[5], q[6], q[7]),
            ]
        };
        Children {
            lo: [
                f(&node.child_min_x),
                f(&node.child_min_y),
                f(&node.child_min_z),
            ],
            hi: [
                f(&node.child_max_x),
                f(&node.child_max_y),
                f(&node.child_max_z),
            ],
        }
    }

    /// The children whose boxes `ray` enters (bit `c` for child slot
    /// `c`), by obvhs's test for a node with corner `p` and cell size
    /// `extent`: per axis `q · (extent · inv) + (p − origin) · inv`,
    /// multiplied then added; the entry the largest of x, then of y and z,
    /// floored at `EPSILON`; the exit the smallest (SSE `max`/`min`).
    #[inline(always)]
    fn hit(&self, p: [f32; 3], extent: [f32; 3], ray: &PacketRay) -> u32 {
        // t[axis][half] = (entry, exit) of children 4·half..4·half + 4.
        let t: [[(Vec4, Vec4); 2]; 3] = std::array::from_fn(|k| {
            let inv = ray.inv[k];
            let scale = Vec4::splat(extent[k] * inv);
            let offset = Vec4::splat((p[k] - ray.org[k]) * inv);
            let (near, far) = if ray.negative[k] {
                (&self.hi[k], &self.lo[k])
            } else {
                (&self.lo[k], &self.hi[k])
            };
            std::array::from_fn(|h| (near[h] * scale + offset, far[h] * scale + offset))
        });
        let mut mask = 0;
        for (h, [x, y, z]) in [0, 1]
            .map(|h| [t[0][h], t[1][h], t[2][h]])
            .into_iter()
            .enumerate()
        {
            let tmin = x.0.max(y.0.max(z.0)).max(Vec4::splat(EPSILON));
            let tmax = x.1.min(y.1.min(z.1)).min(Vec4::splat(ray.tmax));
            mask |= tmin.cmple(tmax).bitmask() << (4 * h);
        }
        mask
    }
}

/// Which rays of `rays` (at most [`PACKET`]) hit a triangle of `tris`
/// (bit `i` for ray `i`): each ray's answer from `bvh` as obvhs's
/// `ray_traverse_miss` with the watertight test would give it.
fn occluded(bvh: &CwBvh, tris: &[Tri], rays: &[PacketRay], stack: &mut Vec<(u32, u64)>) -> u64 {
    debug_assert!(rays.len() <= PACKET);
    let all = if rays.len() >= PACKET {
        u64::MAX
    } else {
        (1u64 << rays.len()) - 1
    };
    if bvh.nodes.is_empty() || all == 0 {
        return 0;
    }
    let mut hit = 0u64;
    stack.clear();
    stack.push((0, all));
    while let Some((index, mask)) = stack.pop() {
        let mask = mask & !hit;
        if mask == 0 {
            continue;
        }
        let node = &bvh.nodes[index as usize];
        let children = Children::of(node);
        let e = node.compute_extent();
        let (p, extent) = (node.p.to_array(), [e.x, e.y, e.z]);
        let mut reach = [0u64; 8];
        let mut m = mask;
        while m != 0 {
            let i = m.trailing_zeros() as usize;
            m &= m - 1;
            let mut c = children.hit(p, extent, &rays[i]);
            while c != 0 {
                let slot = c.trailing_zeros() as usize;
                c &= c - 1;
                reach[slot] |= 1 << i;
            }
        }
        // Leaves now, inner children later.
        for (slot, &rays_in) in reach.iter().enumerate() {
            if rays_in == 0 || node.is_child_empty(slot) {
                continue;
            }
            if node.is_leaf(slot) {
                hit |= leaf(node, slot, tris, rays, rays_in & !hit);
                if hit & mask == mask {
                    break;
                }
            } else {
                stack.push((node.child_node_index(slot), rays_in));
            }
        }
    }
    hit & all
}

/// The rays of `mask` that hit a triangle of leaf child `slot` of `node`.
#[inline(always)]
fn leaf(node: &CwBvhNode, slot: usize, tris: &[Tri], rays: &[PacketRay], mut mask: u64) -> u64 {
    let (start, count) = node.child_primitives(slot);
    let mut hit = 0;
    for id in start..start + count {
        let tri = &tris[id as usize];
        let mut m = mask;
        while m != 0 {
            let i = m.trailing_zeros() as usize;
            m &= m - 1;
            // Strictly closer than the reach, as obvhs's any-hit test.
            let tmax = rays[i].tmax;
            if rays[i].wt.hit(tri, 0.0, tmax) < tmax {
                hit |= 1 << i;
            }
        }
        mask &= !hit;
    }
    hit
}
