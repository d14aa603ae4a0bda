//! Non-line-of-sight (NLOS) capture: a laser lights a spot on a visible relay wall, light goes
//! around the corner to hidden objects and back, and a time-resolved sensor records the light
//! leaving a grid of points on the wall (shaders/lib/nlos.wesl).
//!
//! Conventions (those of Mitsuba 3 + mitransient's `nlos_capture_meter`, so that outputs compare
//! bin for bin):
//! - The relay wall is a mesh node of the scene, named (`relay_wall` by default). Its TEXCOORD_0
//!   parameterises it: grid cell (i, j) of a W x H grid is sensed at the wall point of texture
//!   coordinates ((i + 0.5) / W, (j + 0.5) / H). Pixel (i, j) of the image (row j) is that cell,
//!   so the output's [grid_y, grid_x] is [j, i].
//! - A pixel's value is the radiance (W m^-2 sr^-1) leaving its sensed point towards the sensor
//!   origin, binned by path length: the ray from the sensor origin to the point is traced, and
//!   the first surface it hits is the sensed point.
//! - The laser is a beam of power P (W) from the laser origin towards a target on the wall; the
//!   first surface it hits is the spot. The spot reflects the beam with the wall's BSDF, so it
//!   acts as a point light of radiant intensity P f(to laser, w) cos(w) (W sr^-1).
//! - Path lengths run from the laser spot to the sensed point. The laser origin -> spot and
//!   sensed point -> sensor origin segments are added only with `count_first_and_last`
//!   (mitransient's `account_first_and_last_bounces`, off by default there and here).
//! - Bounces count every scattering vertex, the laser spot and the sensed point included: the
//!   classic three-bounce path spot -> hidden point -> sensed point has 3.
//! - The scene's own lights take no part in a capture.

use anyhow::{Context as _, Result, bail, ensure};
use glam::{Vec2, Vec3};

use crate::bvh::traverse::trace_closest;
use crate::gpu::layout::{NONE, WallPoint};
use crate::scene::{PreparedScene, Scene};

/// The relay wall's node name when none is given.
pub const DEFAULT_RELAY_WALL: &str = "relay_wall";

/// How the laser moves during a capture (`--nlos`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Scan {
    /// One laser spot for the whole grid of sensed points.
    Single,
    /// The laser spot follows the sensed point: each pixel is lit at the point it senses.
    Confocal,
    /// Every laser spot of a laser grid with every sensed point: one single-scan capture per
    /// laser spot.
    Exhaustive,
}

impl Scan {
    /// The name on the command line and in metadata.
    pub fn name(self) -> &'static str {
        match self {
            Scan::Single => "single",
            Scan::Confocal => "confocal",
            Scan::Exhaustive => "exhaustive",
        }
    }
}

/// Where one render's laser spot lies.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LaserAim {
    /// Aimed at the wall point of texture coordinates (u, v) for every pixel.
    Spot(Vec2),
    /// Aimed at each pixel's sensed point (confocal).
    Confocal,
}

/// One NLOS render: the wall, the origins, the laser (what [`crate::integrator::RenderSettings`]
/// carries). The image's width and height are the grid of sensed points.
#[derive(Clone, Debug, PartialEq)]
pub struct NlosCapture {
    /// Name of the relay wall's glTF node.
    pub relay_wall: String,
    /// Where the sensor looks at the wall from (m).
    pub sensor_origin: Vec3,
    /// Where the laser beam starts (m).
    pub laser_origin: Vec3,
    /// Where the beam is aimed.
    pub aim: LaserAim,
    /// Beam power (W).
    pub laser_power: f32,
    /// Count the laser origin -> spot and sensed point -> sensor origin segments in path lengths.
    pub count_first_and_last: bool,
}

/// The origin named by node `name` of the scene, else by node `nlos_origin`: the default of the
/// sensor and laser origins.
pub fn origin_from_nodes(scene: &Scene, name: &str) -> Option<Vec3> {
    scene.node(name).or_else(|| scene.node("nlos_origin")).map(|n| n.position)
}

/// Texture coordinates of the centre of cell (i, j) of a width x height grid.
pub fn cell_uv(i: u32, j: u32, width: u32, height: u32) -> Vec2 {
    Vec2::new((i as f32 + 0.5) / width as f32, (j as f32 + 0.5) / height as f32)
}

/// The point of the relay wall at texture coordinates `uv` (m): interpolated on the first wall
/// triangle whose TEXCOORD_0 triangle holds uv.
pub fn wall_point_at(scene: &Scene, wall: &str, uv: Vec2) -> Result<Vec3> {
    Ok(wall_target_at(scene, wall, uv)?.position)
}

/// A point of the relay wall and where it lies in the scene's triangles.
#[derive(Clone, Copy, Debug)]
pub struct WallTarget {
    /// The point (m).
    pub position: Vec3,
    /// Its triangle: an index into the scene's triangles (load order, not BVH order).
    pub triangle: usize,
    /// Barycentric coordinate of the point on that triangle (weight of vertex 1).
    pub b1: f32,
    /// Barycentric coordinate of the point on that triangle (weight of vertex 2).
    pub b2: f32,
}

/// [`wall_point_at`], with the triangle and barycentric coordinates of the point.
pub fn wall_target_at(scene: &Scene, wall: &str, uv: Vec2) -> Result<WallTarget> {
    let name = &scene.source;
    let node = scene.node(wall).with_context(|| {
        format!("{name}: no node named `{wall}`: an NLOS capture needs the relay wall's mesh node (see --relay-wall)")
    })?;
    ensure!(!node.triangles.is_empty(), "{name}: node `{wall}` (the relay wall) has no mesh");
    let texcoords = node.texcoords.as_ref().with_context(|| {
        format!(
            "{name}: node `{wall}` (the relay wall) has no TEXCOORD_0: the sensed-point grid is laid on the wall's \
             texture coordinates, so give its mesh a TEXCOORD_0 covering [0, 1]^2"
        )
    })?;
    for (k, t) in node.triangles.clone().zip(texcoords) {
        let [a, b, c] = *t;
        let (e1, e2, p) = (b - a, c - a, uv - a);
        let det = e1.perp_dot(e2);
        if det == 0.0 {
            continue;
        }
        let b1 = p.perp_dot(e2) / det;
        let b2 = e1.perp_dot(p) / det;
        let tol = -1e-6;
        if b1 >= tol && b2 >= tol && b1 + b2 <= 1.0 - tol {
            // Onto the triangle itself where uv lies a rounding error outside it.
            let (b1, b2) = (b1.clamp(0.0, 1.0), b2.clamp(0.0, 1.0));
            let (b1, b2) = if b1 + b2 > 1.0 { (b1 / (b1 + b2), b2 / (b1 + b2)) } else { (b1, b2) };
            let [p0, p1, p2] = scene.triangles[k].positions;
            return Ok(WallTarget { position: p0 + b1 * (p1 - p0) + b2 * (p2 - p0), triangle: k, b1, b2 });
        }
    }
    bail!("{name}: the relay wall `{wall}`'s texture coordinates do not cover ({}, {})", uv.x, uv.y)
}

/// What a ray from `origin` towards a wall point meets first: a wall point with no power and
/// no length offset yet, and whether it is the target itself (and not something in front).
/// Where nothing lies in front, the point is the target on its own triangle: a ray aimed at an
/// edge between two triangles of the wall (the diagonal of a two-triangle wall holds the centres
/// of a square grid's diagonal cells) can pass between them in f32 and hit nothing.
/// `bvh_position`: the BVH position of every scene triangle ([`crate::bvh::Bvh::positions`]).
fn first_hit(scene: &PreparedScene, bvh_position: &[u32], origin: Vec3, target: &WallTarget) -> (WallPoint, bool) {
    let to = target.position - origin;
    let distance = to.length();
    let direction = to / distance;
    let hit = trace_closest(&scene.bvh.nodes, &scene.triangles, origin, direction, f32::MAX, NONE);
    let tolerance = 1e-4 * distance.max(1.0);
    if hit.triangle == NONE || hit.t >= distance - tolerance {
        let point = WallPoint {
            position: target.position,
            origin,
            triangle: bvh_position[target.triangle],
            b1: target.b1,
            b2: target.b2,
            ..Default::default()
        };
        return (point, true);
    }
    let tri = &scene.triangles[hit.triangle as usize];
    let position = tri.v0 + hit.b1 * tri.e1 + hit.b2 * tri.e2;
    let point = WallPoint { position, origin, triangle: hit.triangle, b1: hit.b1, b2: hit.b2, ..Default::default() };
    (point, false)
}

/// The `wall_points` table of a width x height capture: the sensed point of every pixel
/// (row-major), then the laser spot of every pixel.
pub fn wall_points(scene: &PreparedScene, capture: &NlosCapture, width: u32, height: u32) -> Result<Vec<WallPoint>> {
    Ok(wall_points_and_warnings(scene, capture, width, height)?.0)
}

/// [`wall_points`], and warnings about sensed points hidden from the sensor origin and a laser
/// beam blocked before its target.
pub fn wall_points_and_warnings(
    scene: &PreparedScene,
    capture: &NlosCapture,
    width: u32,
    height: u32,
) -> Result<(Vec<WallPoint>, Vec<String>)> {
    let mut warnings = Vec::new();
    let name = &scene.scene.source;
    let wall = &capture.relay_wall;
    let pixels = (width * height) as usize;
    let mut points = Vec::with_capacity(2 * pixels);
    let mut targets = Vec::with_capacity(pixels);
    let mut hidden = 0;
    let bvh_position = scene.bvh.positions();
    for j in 0..height {
        for i in 0..width {
            let target = wall_target_at(&scene.scene, wall, cell_uv(i, j, width, height))?;
            let (mut p, on_target) = first_hit(scene, &bvh_position, capture.sensor_origin, &target);
            hidden += !on_target as usize;
            let d = (p.position - capture.sensor_origin).length();
            p.length_offset = if capture.count_first_and_last { 0.0 } else { -d };
            points.push(p);
            targets.push(target);
        }
    }
    if hidden > 0 {
        warnings.push(format!(
            "{name}: {hidden} of {pixels} sensed points of `{wall}` are hidden from the sensor origin {}: those \
             pixels sense what is in front of them",
            fmt_point(capture.sensor_origin)
        ));
    }
    let mut blocked = Vec::new();
    let power = Vec3::splat(capture.laser_power);
    let mut spot = |target: &WallTarget| -> Result<WallPoint> {
        let (mut p, on_target) = first_hit(scene, &bvh_position, capture.laser_origin, target);
        if !on_target {
            blocked.push(format!(
                "{name}: the laser beam from {} towards {} meets other geometry first, at {}",
                fmt_point(capture.laser_origin),
                fmt_point(target.position),
                fmt_point(p.position)
            ));
        }
        p.power = power;
        p.length_offset = if capture.count_first_and_last { (p.position - capture.laser_origin).length() } else { 0.0 };
        Ok(p)
    };
    match capture.aim {
        LaserAim::Spot(uv) => {
            let s = spot(&wall_target_at(&scene.scene, wall, uv)?)?;
            points.extend(std::iter::repeat_n(s, pixels));
        }
        LaserAim::Confocal => {
            for t in &targets {
                points.push(spot(t)?);
            }
        }
    }
    if let Some(first) = blocked.first() {
        let more = blocked.len() - 1;
        warnings.push(if more > 0 { format!("{first} (and {more} more spots)") } else { first.clone() });
    }
    Ok((points, warnings))
}

/// Checks a capture's settings against the scene before any work: the wall exists and is
/// parameterised, the origins are finite and the laser power positive.
pub fn check_capture(scene: &Scene, capture: &NlosCapture) -> Result<()> {
    wall_point_at(scene, &capture.relay_wall, Vec2::splat(0.5))?;
    for (what, p) in [("sensor origin", capture.sensor_origin), ("laser origin", capture.laser_origin)] {
        ensure!(p.is_finite(), "the {what} {} is not finite", fmt_point(p));
    }
    ensure!(
        capture.laser_power.is_finite() && capture.laser_power > 0.0,
        "laser power {} W must be positive",
        capture.laser_power
    );
    if let LaserAim::Spot(uv) = capture.aim {
        ensure!(
            (0.0..=1.0).contains(&uv.x) && (0.0..=1.0).contains(&uv.y),
            "laser spot ({}, {}) must lie in [0, 1]^2 of the relay wall's texture coordinates",
            uv.x,
            uv.y
        );
    }
    Ok(())
}

/// Unit normal of a wall point's surface on the side of its origin (zero when it hit nothing).
pub fn wall_normal(scene: &PreparedScene, p: &WallPoint) -> Vec3 {
    if p.triangle == NONE {
        return Vec3::ZERO;
    }
    let n = crate::scene::surface::octahedral_decode(scene.normals[p.triangle as usize]);
    if n.dot(p.origin - p.position) < 0.0 { -n } else { n }
}

/// Positions and normals of `points` as nested JSON arrays [rows][columns][3].
fn grid_json(scene: &PreparedScene, points: &[WallPoint], width: u32) -> (serde_json::Value, serde_json::Value) {
    let rows = |f: &dyn Fn(&WallPoint) -> Vec3| -> serde_json::Value {
        points
            .chunks(width as usize)
            .map(|row| row.iter().map(|p| f(p).to_array().to_vec()).collect::<Vec<_>>())
            .collect()
    };
    (rows(&|p| p.position), rows(&|p| wall_normal(scene, p)))
}

/// What the JSON sidecar of a capture records: the setup, and the sensed points and laser spots
/// with their normals as [rows][columns][3] arrays (m). `laser_spots` are the spots of a whole
/// scan, `laser_width` per row: one for a single scan, the grid for confocal and exhaustive ones.
pub fn capture_record(
    scene: &PreparedScene,
    capture: &NlosCapture,
    scan: Scan,
    sensed: &[WallPoint],
    width: u32,
    laser_spots: &[WallPoint],
    laser_width: u32,
) -> serde_json::Map<String, serde_json::Value> {
    use serde_json::json;
    let (sensor_xyz, sensor_normals) = grid_json(scene, sensed, width);
    let (laser_xyz, laser_normals) = grid_json(scene, laser_spots, laser_width);
    let mut map = serde_json::Map::new();
    map.insert("nlos_scan".into(), json!(scan.name()));
    map.insert("relay_wall".into(), json!(capture.relay_wall));
    map.insert("sensor_origin".into(), json!(capture.sensor_origin.to_array()));
    map.insert("laser_origin".into(), json!(capture.laser_origin.to_array()));
    map.insert("laser_power_w".into(), json!(capture.laser_power));
    map.insert("count_first_and_last".into(), json!(capture.count_first_and_last));
    map.insert("sensor_grid_xyz".into(), sensor_xyz);
    map.insert("sensor_grid_normals".into(), sensor_normals);
    map.insert("laser_grid_xyz".into(), laser_xyz);
    map.insert("laser_grid_normals".into(), laser_normals);
    map
}

fn fmt_point(p: Vec3) -> String {
    format!("({}, {}, {}) m", p.x, p.y, p.z)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cells_are_centred() {
        assert_eq!(cell_uv(0, 0, 4, 2), Vec2::new(0.125, 0.25));
        assert_eq!(cell_uv(3, 1, 4, 2), Vec2::new(0.875, 0.75));
    }
}

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
