//! The hidden scene's preparation for the band index's shell connections: closed double-sided
//! meshes made one-sided, and triangles larger than the bins resolve cut into pieces.

use anyhow::{Result, ensure};
use glam::{Vec2, Vec3};

use crate::scene::Scene;

/// Pieces per edge (k: a triangle becomes k^2) of the largest refinement `refine_for_shells`
/// makes.
pub const MAX_REFINE_PIECES: u32 = 256;
/// The finest bins (m, 4 ps) `refine_for_shells` cuts for: finer bins would multiply the band
/// index's entries (about in proportion to the pieces' number over their size) beyond the
/// device's memory and its build time, while pieces cut for 4 ps overshoot a 1 ps bin by at most
/// its width.
pub const REFINE_FINEST_BIN: f64 = 0.0012;
/// Most triangles `refine_for_shells` leaves a scene with (unless it had more).
pub const MAX_REFINED_TRIANGLES: u64 = 1 << 23;

/// What `prepare_for_shells` did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ShellPreparation {
    /// Closed meshes whose double-sided materials became one-sided.
    pub closed_meshes: usize,
    /// Triangles cut into pieces.
    pub refined: usize,
    /// Triangles of the scene afterwards.
    pub triangles: usize,
}

/// Prepares a capture's scene for the shell connections of the band index (band_index.wesl)
/// at bins `bin_width` metres wide: `close_surfaces`, then `refine_for_shells`. `outside`: the
/// points every path starts and ends beyond the hidden scene (the sensor and laser origins).
pub fn prepare_for_shells(
    scene: &mut Scene,
    relay_wall: &str,
    bin_width: f64,
    outside: &[Vec3],
) -> Result<ShellPreparation> {
    let closed_meshes = close_surfaces(scene, relay_wall, outside)?;
    let mut done = refine_for_shells(scene, relay_wall, bin_width)?;
    done.closed_meshes = closed_meshes;
    Ok(done)
}

/// Makes the double-sided materials of closed meshes one-sided, where that changes no path: a
/// named node's mesh that is watertight and consistently wound with its normals outwards
/// (every edge shared by exactly two triangles, in opposite directions; positive signed volume)
/// and whose bounding box holds neither the relay wall nor any point of `outside`. Every path of
/// a capture then runs outside it (the spot and the sensed points lie on the wall, the origins
/// beyond, and nothing transmits), and a ray from outside meets its outer face first, so its
/// inner faces take no part. A shell connection has no shadow ray to tell an inner face from an
/// outer one until it has drawn it: on a closed hidden object, half its triangles face the wall
/// from inside, and as one-sided they get no mass. Returns the meshes changed.
pub fn close_surfaces(scene: &mut Scene, relay_wall: &str, outside: &[Vec3]) -> Result<usize> {
    use std::collections::HashMap;
    let wall = scene.node(relay_wall).map(|n| n.triangles.clone()).unwrap_or(0..0);
    let bounds = |range: std::ops::Range<usize>, scene: &Scene| {
        let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
        for t in &scene.triangles[range] {
            for p in t.positions {
                (lo, hi) = (lo.min(p), hi.max(p));
            }
        }
        (lo, hi)
    };
    let (wall_lo, wall_hi) = bounds(wall.clone(), scene);
    let mut changed = 0;
    let mut one_sided: HashMap<u32, u32> = HashMap::new();
    let ranges: Vec<std::ops::Range<usize>> = scene.nodes.iter().map(|n| n.triangles.clone()).collect();
    for range in ranges {
        if range.is_empty()
            || range == wall
            || !scene.triangles[range.clone()].iter().any(|t| scene.materials[t.material as usize].double_sided)
        {
            continue;
        }
        let (lo, hi) = bounds(range.clone(), scene);
        let inside = |p: Vec3| p.cmpge(lo).all() && p.cmple(hi).all();
        if outside.iter().any(|&p| inside(p)) || (wall_lo.cmple(hi).all() && wall_hi.cmpge(lo).all()) {
            continue;
        }
        // Watertight and consistently wound: each directed edge once, its reverse once.
        let key = |p: Vec3| [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()];
        let mut edges: HashMap<([u32; 3], [u32; 3]), i32> = HashMap::with_capacity(3 * range.len());
        let mut volume = 0.0f64;
        for t in &scene.triangles[range.clone()] {
            let [a, b, c] = t.positions;
            volume += a.as_dvec3().dot(b.as_dvec3().cross(c.as_dvec3()));
            for (u, v) in [(a, b), (b, c), (c, a)] {
                *edges.entry((key(u), key(v))).or_insert(0) += 1;
            }
        }
        let closed = edges.iter().all(|(&(u, v), &n)| n == 1 && edges.get(&(v, u)) == Some(&1));
        if !closed || !(volume > 0.0) {
            continue;
        }
        for t in &mut scene.triangles[range.clone()] {
            let material = &scene.materials[t.material as usize];
            if material.double_sided {
                let next = scene.materials.len() as u32;
                t.material = *one_sided.entry(t.material).or_insert_with(|| next);
                if t.material == next {
                    let mut m = material.clone();
                    m.double_sided = false;
                    m.name = format!("{} (closed surface)", m.name);
                    scene.materials.push(m);
                }
            }
        }
        changed += 1;
    }
    Ok(changed)
}

/// Cuts the triangles of a capture's hidden scene into pieces small enough for the shell
/// connections of the band index (band_index.wesl) at bins `bin_width` metres wide: over a
/// piece the path length must stay close to linear and the contribution close to constant. A
/// piece a distance d from the relay wall (where every focus lies) gets edges of at most
/// min(sqrt(0.75 w d), d / 20), w the bin width (at least REFINE_FINEST_BIN): its strip then
/// overshoots a bin of w by at most a quarter (eps = K e^2 / 6 with K <= 2 / d) and its 1 / d^4
/// falls by at most a fifth across it.
/// Each triangle becomes k x k congruent pieces (k <= MAX_REFINE_PIECES; normals and texture
/// coordinates interpolated), in place, so every node keeps its triangles contiguous. The relay
/// wall's own triangles, on which no three-bounce connection reflects, are kept whole.
pub fn refine_for_shells(scene: &mut Scene, relay_wall: &str, bin_width: f64) -> Result<ShellPreparation> {
    let wall = scene.node(relay_wall).map(|n| n.triangles.clone()).unwrap_or(0..0);
    ensure!(!wall.is_empty(), "the relay wall `{relay_wall}` has no triangles");
    let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
    for t in &scene.triangles[wall.clone()] {
        for p in t.positions {
            (lo, hi) = (lo.min(p), hi.max(p));
        }
    }
    // Pieces per edge with edges `scale` times the targets.
    let pieces = |t: &crate::scene::SceneTriangle, scale: f64| -> u32 {
        let [a, b, c] = t.positions;
        let longest = a.distance(b).max(a.distance(c)).max(b.distance(c)) as f64;
        // The nearest vertex's distance from the wall's box (at least 1 cm) stands for d.
        let d =
            [a, b, c].iter().map(|&p| (p - p.clamp(lo, hi)).length()).fold(f32::INFINITY, f32::min).max(0.01) as f64;
        let edge = scale * (0.75 * bin_width.max(REFINE_FINEST_BIN) * d).sqrt().min(d / 20.0);
        (longest / edge).ceil().clamp(1.0, MAX_REFINE_PIECES as f64) as u32
    };
    let count = |scale: f64| -> Vec<u32> {
        scene.triangles.iter().enumerate().map(|(i, t)| if wall.contains(&i) { 1 } else { pieces(t, scale) }).collect()
    };
    // A scene the targets would cut into more than MAX_REFINED_TRIANGLES gets coarser pieces
    // (still unbiased: the strips' overshoot and the contribution's change across a piece only
    // cost samples).
    let total = |counts: &[u32]| counts.iter().map(|&k| (k as u64) * (k as u64)).sum::<u64>();
    let mut scale = 1.0;
    let mut counts = count(scale);
    while total(&counts) > MAX_REFINED_TRIANGLES && scale < 1e6 {
        scale *= 1.05 * (total(&counts) as f64 / MAX_REFINED_TRIANGLES as f64).sqrt();
        counts = count(scale);
    }
    let total = total(&counts);
    let mut starts = Vec::with_capacity(counts.len() + 1);
    let mut triangles = Vec::with_capacity(total as usize);
    let mut refined = 0;
    for (t, &k) in scene.triangles.iter().zip(&counts) {
        starts.push(triangles.len());
        if k == 1 {
            triangles.push(t.clone());
            continue;
        }
        refined += 1;
        for (w0, w1, w2) in sub_triangles(k) {
            let mix3 = |v: [Vec3; 3], w: Vec3| v[0] * w.x + v[1] * w.y + v[2] * w.z;
            let mix2 = |v: [Vec2; 3], w: Vec3| v[0] * w.x + v[1] * w.y + v[2] * w.z;
            triangles.push(crate::scene::SceneTriangle {
                positions: [mix3(t.positions, w0), mix3(t.positions, w1), mix3(t.positions, w2)],
                normals: t.normals.map(|n| [w0, w1, w2].map(|w| mix3(n, w).normalize_or(n[0]))),
                uvs: [mix2(t.uvs, w0), mix2(t.uvs, w1), mix2(t.uvs, w2)],
                material: t.material,
            });
        }
    }
    starts.push(triangles.len());
    for node in &mut scene.nodes {
        let (a, b) = (node.triangles.start, node.triangles.end);
        if let Some(texcoords) = &node.texcoords {
            let mut refined_uv = Vec::with_capacity(starts[b] - starts[a]);
            for (uv, &k) in texcoords.iter().zip(&counts[a..b]) {
                if k == 1 {
                    refined_uv.push(*uv);
                } else {
                    let mix2 = |w: Vec3| uv[0] * w.x + uv[1] * w.y + uv[2] * w.z;
                    refined_uv.extend(sub_triangles(k).map(|(w0, w1, w2)| [mix2(w0), mix2(w1), mix2(w2)]));
                }
            }
            node.texcoords = Some(refined_uv);
        }
        node.triangles = starts[a]..starts[b];
    }
    scene.triangles = triangles;
    Ok(ShellPreparation { closed_meshes: 0, refined, triangles: scene.triangles.len() })
}

/// The k^2 congruent sub-triangles of a triangle as barycentric corners (weights of its three
/// vertices), counter-clockwise like it: k(k+1)/2 pointing as it does, k(k-1)/2 the other way.
fn sub_triangles(k: u32) -> impl Iterator<Item = (Vec3, Vec3, Vec3)> {
    let f = 1.0 / k as f32;
    let at = move |i: u32, j: u32| Vec3::new(1.0 - (i + j) as f32 * f, i as f32 * f, j as f32 * f);
    (0..k).flat_map(move |i| {
        (0..k - i).flat_map(move |j| {
            let up = std::iter::once((at(i, j), at(i + 1, j), at(i, j + 1)));
            let down = (i + j + 1 < k).then(|| (at(i + 1, j), at(i + 1, j + 1), at(i, j + 1)));
            up.chain(down)
        })
    })
}
