//! The relay wall's points: the sensed point of every pixel and the laser spots (first hits
//! of rays from the sensor and laser origins), their checks and warnings, and the capture's
//! record in the JSON sidecar.

use anyhow::{Context as _, Result, bail, ensure};
use glam::{Vec2, Vec3};

use super::{Laser, LaserAim, NlosCapture, Scan};
use crate::bvh::traverse::trace_closest;
use crate::gpu::layout::{NONE, WallPoint};
use crate::scene::{PreparedScene, Scene};

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
        p.power = capture.laser.spot_power(capture.laser_origin, p.position, wall_normal(scene, &p));
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
/// parameterised, the origins are finite and the laser gives power.
pub fn check_capture(scene: &Scene, capture: &NlosCapture) -> Result<()> {
    wall_point_at(scene, &capture.relay_wall, Vec2::splat(0.5))?;
    for (what, p) in [("sensor origin", capture.sensor_origin), ("laser origin", capture.laser_origin)] {
        ensure!(p.is_finite(), "the {what} {} is not finite", fmt_point(p));
    }
    capture.laser.check()?;
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
    let (power, projector) = match capture.laser {
        Laser::Beam(power) => (json!(power), json!(null)),
        Laser::Projector(irradiance) => (json!(null), json!(irradiance.to_array())),
    };
    map.insert("laser_power_w".into(), power);
    map.insert("laser_projector_irradiance_w_m2".into(), projector);
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
