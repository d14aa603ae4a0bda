//! The binary BVH's stackless traversal on the CPU, in f32: the host's own ray casts (an NLOS
//! capture's sensed points and laser spots) and an oracle of the tests, itself checked against
//! brute force. The kernels' rays traverse the wide BVH, whose twin is `wide.rs`.

use glam::Vec3;

use crate::gpu::layout::{BvhNode, Hit, NONE, Triangle};

/// Moller-Trumbore; (t, b1, b2) with t < 0 for a miss.
pub fn intersect_triangle(origin: Vec3, direction: Vec3, v0: Vec3, e1: Vec3, e2: Vec3) -> (f32, f32, f32) {
    let p = direction.cross(e2);
    let det = e1.dot(p);
    if det == 0.0 {
        return (-1.0, 0.0, 0.0);
    }
    let inv_det = 1.0 / det;
    let s = origin - v0;
    let b1 = s.dot(p) * inv_det;
    if !(0.0..=1.0).contains(&b1) {
        return (-1.0, 0.0, 0.0);
    }
    let q = s.cross(e1);
    let b2 = direction.dot(q) * inv_det;
    if b2 < 0.0 || b1 + b2 > 1.0 {
        return (-1.0, 0.0, 0.0);
    }
    (e2.dot(q) * inv_det, b1, b2)
}

/// 1 / direction with zero components replaced by a tiny value of their sign, so the slab tests
/// never compute 0 * inf (twin of bvh.wesl `safe_inverse`; both BVHs' traversals use it).
pub fn safe_inverse(d: Vec3) -> Vec3 {
    let tiny = 1e-30f32;
    let fix = |x: f32| if x.abs() < tiny { if x >= 0.0 { tiny } else { -tiny } } else { x };
    Vec3::new(1.0 / fix(d.x), 1.0 / fix(d.y), 1.0 / fix(d.z))
}

fn ray_hits_box(origin: Vec3, inv_dir: Vec3, lo: Vec3, hi: Vec3, t_max: f32) -> bool {
    let t0 = (lo - origin) * inv_dir;
    let t1 = (hi - origin) * inv_dir;
    let near = t0.min(t1);
    let far = t0.max(t1);
    let t_near = near.x.max(near.y).max(near.z.max(0.0));
    let t_far = far.x.min(far.y).min(far.z.min(t_max));
    t_near <= t_far
}

/// Closest hit with t in (0, t_max), ignoring triangle `ignore`.
pub fn trace_closest(
    nodes: &[BvhNode],
    triangles: &[Triangle],
    origin: Vec3,
    direction: Vec3,
    t_max: f32,
    ignore: u32,
) -> Hit {
    let mut best = Hit { t: t_max, triangle: NONE, b1: 0.0, b2: 0.0 };
    let inv_dir = safe_inverse(direction);
    let mut i = 0usize;
    while i < nodes.len() {
        let node = &nodes[i];
        if !ray_hits_box(origin, inv_dir, node.min, node.max, best.t) {
            i = node.skip as usize;
            continue;
        }
        let Some(range) = node.leaf_range() else {
            i += 1;
            continue;
        };
        for k in range {
            if k == ignore {
                continue;
            }
            let tri = &triangles[k as usize];
            let (t, b1, b2) = intersect_triangle(origin, direction, tri.v0, tri.e1, tri.e2);
            if t > 0.0 && t < best.t {
                best = Hit { t, triangle: k, b1, b2 };
            }
        }
        i = node.skip as usize;
    }
    best
}

/// Any hit with t in (0, t_max) other than `ignore0`, `ignore1`.
pub fn trace_any(
    nodes: &[BvhNode],
    triangles: &[Triangle],
    origin: Vec3,
    direction: Vec3,
    t_max: f32,
    ignore0: u32,
    ignore1: u32,
) -> bool {
    let inv_dir = safe_inverse(direction);
    let mut i = 0usize;
    while i < nodes.len() {
        let node = &nodes[i];
        if !ray_hits_box(origin, inv_dir, node.min, node.max, t_max) {
            i = node.skip as usize;
            continue;
        }
        let Some(range) = node.leaf_range() else {
            i += 1;
            continue;
        };
        for k in range {
            if k == ignore0 || k == ignore1 {
                continue;
            }
            let tri = &triangles[k as usize];
            let (t, _, _) = intersect_triangle(origin, direction, tri.v0, tri.e1, tri.e2);
            if t > 0.0 && t < t_max {
                return true;
            }
        }
        i = node.skip as usize;
    }
    false
}

/// Brute-force closest hit over every triangle: the oracle of the oracle.
pub fn brute_force_closest(triangles: &[Triangle], origin: Vec3, direction: Vec3, t_max: f32, ignore: u32) -> Hit {
    let mut best = Hit { t: t_max, triangle: NONE, b1: 0.0, b2: 0.0 };
    for (k, tri) in triangles.iter().enumerate() {
        if k as u32 == ignore {
            continue;
        }
        let (t, b1, b2) = intersect_triangle(origin, direction, tri.v0, tri.e1, tri.e2);
        if t > 0.0 && t < best.t {
            best = Hit { t, triangle: k as u32, b1, b2 };
        }
    }
    best
}
