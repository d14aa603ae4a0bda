//! The hidden scene's preparation for the band index's shell connections: closed double-sided
//! meshes made one-sided, triangles larger than the bins resolve cut into pieces, and the pieces
//! no light reaches, buried between closed convex solids, dropped.

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
/// Finer cuts `refine_for_shells` tries beyond its edge rule, as divisors of its edges, coarse
/// to fine: the finest whose pieces stay within the capture's `finer_pieces` is taken.
pub const FINER_CUTS: [u32; 3] = [2, 4, 8];

/// What `prepare_for_shells` did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ShellPreparation {
    /// Closed meshes whose double-sided materials became one-sided.
    pub closed_meshes: usize,
    /// Triangles cut into pieces.
    pub refined: usize,
    /// Triangles of the scene afterwards.
    pub triangles: usize,
    /// Closed convex opaque solids found among the hidden scene's meshes (`convex_solids`).
    pub solids: usize,
    /// Pieces dropped because no light reaches them: both their sides lie within solids.
    pub buried: usize,
    /// The pieces' edges are 1/finer_cut of the edge rule's (`FINER_CUTS`; 1: the rule's, or
    /// coarser where they would pass MAX_REFINED_TRIANGLES).
    pub finer_cut: u32,
}

/// Prepares a capture's scene for the shell connections of the band index (band_index.wesl)
/// at bins `bin_width` metres wide: `close_surfaces`, then `refine_for_shells`, then
/// `drop_buried_pieces` over the `convex_solids` of the scene before its refinement. `outside`:
/// the points every path starts and ends beyond the hidden scene (the sensor and laser origins);
/// `finer_pieces`: the most triangles finer cuts than the edge rule may leave (0: none; see
/// `refine_for_shells` and `crate::capture::finer_pieces`).
pub fn prepare_for_shells(
    scene: &mut Scene,
    relay_wall: &str,
    bin_width: f64,
    outside: &[Vec3],
    finer_pieces: u64,
) -> Result<ShellPreparation> {
    let closed_meshes = close_surfaces(scene, relay_wall, outside)?;
    let solids = convex_solids(scene, relay_wall, outside);
    let mut done = refine_for_shells(scene, relay_wall, bin_width, finer_pieces)?;
    done.closed_meshes = closed_meshes;
    done.solids = solids.len();
    done.buried = drop_buried_pieces(scene, relay_wall, &solids);
    done.triangles = scene.triangles.len();
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
        if !closed_outwards(scene.triangles[range.clone()].iter().map(|t| t.positions)) {
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

/// True when `triangles` form a watertight mesh, consistently wound with its normals outwards:
/// each directed edge (vertices compared bit for bit) once and its reverse once, and a positive
/// signed volume.
fn closed_outwards(triangles: impl Iterator<Item = [Vec3; 3]>) -> bool {
    use std::collections::HashMap;
    let mut edges: HashMap<([u32; 3], [u32; 3]), u32> = HashMap::new();
    let mut volume = 0.0f64;
    for [a, b, c] in triangles {
        volume += a.as_dvec3().dot(b.as_dvec3().cross(c.as_dvec3()));
        for (u, v) in [(a, b), (b, c), (c, a)] {
            *edges.entry((vertex_key(u), vertex_key(v))).or_insert(0) += 1;
        }
    }
    volume > 0.0 && edges.iter().all(|(&(u, v), &n)| n == 1 && edges.get(&(v, u)) == Some(&1))
}

/// A vertex's position bit for bit, to find the edges triangles share.
fn vertex_key(p: Vec3) -> [u32; 3] {
    [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()]
}

/// Cuts the triangles of a capture's hidden scene into pieces small enough for the shell
/// connections of the band index (band_index.wesl) at bins `bin_width` metres wide: over a
/// piece the path length must stay close to linear and the contribution close to constant. A
/// piece a distance d from the relay wall (where every focus lies) gets edges of at most
/// min(sqrt(0.75 w d), d / 20), w the bin width (at least REFINE_FINEST_BIN): its strip then
/// overshoots a bin of w by at most a quarter (eps = K e^2 / 6 with K <= 2 / d) and its 1 / d^4
/// falls by at most a fifth across it.
///
/// Finer pieces cost index entries and build time but less variance: a shell connection's
/// estimate is the bin's total mass times the share of its strip's points whose own length lies
/// in the bin, and that share varies from piece to piece by up to the strip's overshoot. Where
/// the edge rule's pieces are few, the edges are cut by the finest of FINER_CUTS that leaves at
/// most `finer_pieces` triangles (0: the edge rule alone). 10 s captures (confocal 16 x 16, 4 ps
/// bins) had 0.47, 0.19 and 0.11 of the error with edges of 1/2, 1/4 and 1/8 of the rule on
/// `nlos_panels.xml`, and 0.63 and 0.66 with 1/2 and 1/4 on `nlos_staircase.xml`
/// (docs/nlos.md, "Finer pieces").
///
/// Each triangle becomes k x k congruent pieces (k <= MAX_REFINE_PIECES; normals and texture
/// coordinates interpolated), in place, so every node keeps its triangles contiguous. The relay
/// wall's own triangles, on which no three-bounce connection reflects, are kept whole.
pub fn refine_for_shells(
    scene: &mut Scene,
    relay_wall: &str,
    bin_width: f64,
    finer_pieces: u64,
) -> Result<ShellPreparation> {
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
    let mut finer_cut = 1;
    if scale == 1.0 {
        for cut in FINER_CUTS {
            let finer_counts = count(1.0 / cut as f64);
            if total(&finer_counts) > finer_pieces.min(MAX_REFINED_TRIANGLES) {
                break;
            }
            counts = finer_counts;
            finer_cut = cut;
        }
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
    Ok(ShellPreparation { refined, triangles: scene.triangles.len(), finer_cut, ..Default::default() })
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

/// Most triangles of a mesh `convex_solids` checks for convexity (every vertex against every
/// face: the check is quadratic).
pub const MAX_SOLID_TRIANGLES: usize = 4096;

/// A closed convex solid of the scene, wound outwards and opaque: the planes of its faces, each
/// (unit outward normal, offset: n . x = offset on the face), in f64.
#[derive(Clone, Debug)]
pub struct ConvexSolid {
    /// Face planes (duplicates of a face's two triangles included).
    pub planes: Vec<(glam::DVec3, f64)>,
    /// Lower corner of the bounding box (m).
    pub lo: glam::DVec3,
    /// Upper corner of the bounding box (m).
    pub hi: glam::DVec3,
    /// How far (m) a point may lie outside a plane and still count as on it: 10^-6 of the
    /// solid's diagonal, well above the f32 rounding of coplanar faces of separate meshes.
    pub tolerance: f64,
}

impl ConvexSolid {
    /// The largest signed distance (m) of `p` from the planes: <= 0 inside or on the solid.
    pub fn outside_by(&self, p: glam::DVec3) -> f64 {
        self.planes.iter().map(|&(n, d)| n.dot(p) - d).fold(f64::NEG_INFINITY, f64::max)
    }
}

/// The hidden scene's closed convex opaque solids, whose insides no path of the capture enters:
/// meshes found as the triangles joined by edges that exactly two of them share, in opposite
/// directions (so that solids which touch along an edge stay apart), each watertight and
/// consistently wound with its normals outwards (positive signed volume), convex (every vertex
/// on or behind every face's plane; meshes of at most MAX_SOLID_TRIANGLES), made of materials
/// that transmit nothing, and holding neither the relay wall, a point of `outside` (where
/// paths start and end), a light nor an emitting triangle. Light that reaches any point inside
/// such a solid would have had to cross its faces.
pub fn convex_solids(scene: &Scene, relay_wall: &str, outside: &[Vec3]) -> Vec<ConvexSolid> {
    use glam::DVec3;
    use std::collections::HashMap;
    let wall = scene.node(relay_wall).map(|n| n.triangles.clone()).unwrap_or(0..0);
    let n = scene.triangles.len();
    // Every triangle's edges as (undirected edge, triangle, direction), sorted so that the
    // triangles of an edge lie together.
    type Edge = ([u32; 3], [u32; 3]);
    let mut edges: Vec<(Edge, usize, bool)> = Vec::with_capacity(3 * n);
    for (i, t) in scene.triangles.iter().enumerate() {
        if wall.contains(&i) {
            continue;
        }
        let [a, b, c] = t.positions.map(vertex_key);
        for (u, v) in [(a, b), (b, c), (c, a)] {
            edges.push(((u.min(v), u.max(v)), i, u < v));
        }
    }
    edges.sort_unstable_by_key(|x| x.0);
    // Union-find over the edges two triangles share in opposite directions and no other holds.
    let mut parent: Vec<usize> = (0..n).collect();
    fn root(parent: &mut [usize], mut i: usize) -> usize {
        while parent[i] != i {
            parent[i] = parent[parent[i]];
            i = parent[i];
        }
        i
    }
    for group in edges.chunk_by(|x, y| x.0 == y.0) {
        if let [(_, a, da), (_, b, db)] = *group
            && da != db
        {
            let (ra, rb) = (root(&mut parent, a), root(&mut parent, b));
            parent[ra] = rb;
        }
    }
    let mut meshes: HashMap<usize, Vec<usize>> = HashMap::new();
    for i in (0..n).filter(|i| !wall.contains(i)) {
        let r = root(&mut parent, i);
        meshes.entry(r).or_default().push(i);
    }
    let wall_points: Vec<DVec3> =
        scene.triangles[wall].iter().flat_map(|t| t.positions.map(|p| p.as_dvec3())).collect();
    let emitters: Vec<DVec3> = scene
        .triangles
        .iter()
        .filter(|t| scene.materials[t.material as usize].is_emissive())
        .flat_map(|t| t.positions.map(|p| p.as_dvec3()))
        .chain(scene.point_lights.iter().map(|l| l.position.as_dvec3()))
        .chain(outside.iter().map(|p| p.as_dvec3()))
        .collect();
    let mut solids = Vec::new();
    let mut roots: Vec<usize> = meshes.keys().copied().collect();
    roots.sort_unstable();
    for r in roots {
        let mesh = &meshes[&r];
        if mesh.len() < 4 || mesh.len() > MAX_SOLID_TRIANGLES {
            continue;
        }
        let opaque = mesh.iter().all(|&i| scene.materials[scene.triangles[i].material as usize].dielectric.is_none());
        if !opaque || !closed_outwards(mesh.iter().map(|&i| scene.triangles[i].positions)) {
            continue;
        }
        let points: Vec<DVec3> =
            mesh.iter().flat_map(|&i| scene.triangles[i].positions.map(|p| p.as_dvec3())).collect();
        let (lo, hi) =
            points.iter().fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(lo, hi), &p| (lo.min(p), hi.max(p)));
        let tolerance = 1e-6 * (hi - lo).length();
        let planes: Vec<(DVec3, f64)> = mesh
            .iter()
            .filter_map(|&i| {
                let [a, b, c] = scene.triangles[i].positions.map(|p| p.as_dvec3());
                let normal = (b - a).cross(c - a).try_normalize()?;
                Some((normal, normal.dot(a)))
            })
            .collect();
        let solid = ConvexSolid { planes, lo, hi, tolerance };
        let convex = points.iter().all(|&p| solid.outside_by(p) <= tolerance);
        // Nothing a path starts from, and no light, within or on it.
        let holds = |p: &DVec3| solid.outside_by(*p) <= tolerance;
        if convex && !wall_points.iter().any(holds) && !emitters.iter().any(holds) {
            solids.push(solid);
        }
    }
    solids
}

/// Drops the hidden scene's triangles (pieces, after `refine_for_shells`) that no light reaches:
/// those of which a thin slab on each side lies within one of the closed convex opaque
/// `solids` (the other side's solid may be another, or the piece's own mesh). For each side
/// s = +-1 some solid holds the piece's vertices and their offsets by s delta n (n the piece's
/// unit normal, delta 10 times the solid's tolerance or a thousandth of the piece's longest edge
/// if larger), and its centroid's offset strictly inside; by convexity every point just off the
/// piece on that side is then inside the solid. A path reaching such a piece from either side
/// would have entered a solid across faces that stay (a face of a solid with a side outside
/// every solid is never dropped), which no path does, so the pieces carry no light: dropping
/// them changes no capture, while shell connections stop drawing points whose shadow rays find
/// them dark (the lower parts of the staircase of boxes' risers, each against the box in front,
/// `nlos_staircase_boxes.xml`). The relay wall is kept. Returns the pieces dropped.
pub fn drop_buried_pieces(scene: &mut Scene, relay_wall: &str, solids: &[ConvexSolid]) -> usize {
    use glam::DVec3;
    if solids.is_empty() {
        return 0;
    }
    let wall = scene.node(relay_wall).map(|n| n.triangles.clone()).unwrap_or(0..0);
    let buried = |t: &crate::scene::SceneTriangle| -> bool {
        let v = t.positions.map(|p| p.as_dvec3());
        let Some(normal) = (v[1] - v[0]).cross(v[2] - v[0]).try_normalize() else {
            return false;
        };
        let (lo, hi) = (v[0].min(v[1]).min(v[2]), v[0].max(v[1]).max(v[2]));
        let longest = v[0].distance(v[1]).max(v[0].distance(v[2])).max(v[1].distance(v[2]));
        let centroid = (v[0] + v[1] + v[2]) / 3.0;
        let held = |side: f64| {
            solids.iter().any(|s| {
                let reach = DVec3::splat(s.tolerance);
                if (lo - reach).cmpgt(s.hi).any() || (hi + reach).cmplt(s.lo).any() {
                    return false;
                }
                let delta = side * (10.0 * s.tolerance).max(1e-3 * longest);
                v.iter().all(|&p| s.outside_by(p) <= s.tolerance && s.outside_by(p + delta * normal) <= s.tolerance)
                    && s.outside_by(centroid + delta * normal) < -s.tolerance
            })
        };
        held(1.0) && held(-1.0)
    };
    let keep: Vec<bool> = scene.triangles.iter().enumerate().map(|(i, t)| wall.contains(&i) || !buried(t)).collect();
    let dropped = keep.iter().filter(|&&k| !k).count();
    if dropped == 0 {
        return 0;
    }
    // New index of each triangle's place (the kept ones before it), for the nodes' ranges.
    let mut starts = Vec::with_capacity(keep.len() + 1);
    let mut kept = 0;
    for &k in &keep {
        starts.push(kept);
        kept += k as usize;
    }
    starts.push(kept);
    for node in &mut scene.nodes {
        let (a, b) = (node.triangles.start, node.triangles.end);
        if let Some(texcoords) = &mut node.texcoords {
            let mut k = keep[a..b].iter();
            texcoords.retain(|_| *k.next().unwrap());
        }
        node.triangles = starts[a]..starts[b];
    }
    let mut k = keep.iter();
    scene.triangles.retain(|_| *k.next().unwrap());
    dropped
}
