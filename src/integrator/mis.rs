//! CPU twin of the multiple-importance weights of bidirectional path tracing
//! (`mis_weight` in shaders/kernels/connect_direct.wesl, the densities of
//! shaders/lib/subpath.wesl, and the forward/reverse densities extend_subpaths stores), of the
//! paper's weights of ellipsoidal connections (shaders/lib/ellipsoidal_mis.wesl) and of the
//! combined estimator's weights over both families (shaders/lib/family_mis.wesl).
//!
//! A full path x_0 (on a light) ... x_{k-1} (the pinhole) can be sampled by k - 1 strategies
//! (s, t) with s + t = k (t >= 1; s = 0 impossible for point lights). The weight of one of them
//! is computed from the subpaths as the kernels store them: each vertex keeps the area density
//! of its own subpath's step (pdf_fwd) and of the opposite direction (pdf_rev), and the four
//! vertices next to the connection get the densities the connection implies.

use std::f32::consts::FRAC_1_PI;

use glam::Vec3;

use crate::sampling::Frame;
use crate::scene::bsdf::Bsdf;

/// What a path vertex is.
// A surface's BSDF may hold a plastic's transmittance table (256 bytes): this CPU twin keeps
// vertices by value for clarity over size.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum VertexKind {
    /// The pinhole; `image_area` is the image's area at unit distance (the camera samples
    /// directions with density 1 / (image_area cos^3) about `normal`, its viewing direction).
    Camera {
        /// Image area on the plane at unit distance.
        image_area: f32,
    },
    /// A point on a one-sided area light (emits cos-weighted about `normal`), chosen with area
    /// density `origin_pdf` (m^-2, selection included).
    AreaLight {
        /// Selection x position density (m^-2).
        origin_pdf: f32,
    },
    /// A point light chosen with probability `select_pdf`; emits uniformly over the sphere.
    PointLight {
        /// Selection probability.
        select_pdf: f32,
    },
    /// A directional light chosen with probability `select_pdf`, whose light subpaths start
    /// uniformly on a disk of area `beam_area` (m^2) across the beam; the vertex's `normal` is
    /// the direction of travel. The first vertex it reaches has area density cos / beam_area,
    /// with no fall-off over distance.
    DirectionalLight {
        /// Selection probability.
        select_pdf: f32,
        /// Area (m^2) of the disk light subpaths start on.
        beam_area: f32,
    },
    /// A surface point with a material.
    Surface(Bsdf),
    /// A scattering point in a participating medium with a Henyey-Greenstein phase function of
    /// mean cosine `g`: no normal, no cosine in its densities (the kernels' VERTEX_MEDIUM). Its
    /// densities, like every other vertex's, leave out the transmittance and the extinction
    /// (extend_subpaths).
    Medium {
        /// Mean cosine of the phase function.
        g: f32,
        /// Extinction there (m^-1): only the combined weights' density of a medium vertex
        /// placed on a spheroid reads it ([`medium_vertex_density`]).
        sigma_t: f32,
    },
}

/// One vertex of a full path. Normals are unit and face the side the path lies on.
#[derive(Clone, Copy, Debug)]
pub struct Vertex {
    /// What the vertex is.
    pub kind: VertexKind,
    /// Position (m).
    pub position: Vec3,
    /// Unit normal (geometric = shading here); the viewing direction for the camera.
    pub normal: Vec3,
}

impl Vertex {
    fn has_area_measure(&self) -> bool {
        matches!(self.kind, VertexKind::Surface(_) | VertexKind::AreaLight { .. })
    }

    /// A vertex on a delta BSDF (a smooth or thin dielectric): no connection ends there, and its
    /// sampled directions have no density (the kernels' VERTEX_DELTA).
    pub fn is_delta(&self) -> bool {
        matches!(self.kind, VertexKind::Surface(bsdf) if bsdf.dielectric.is_some())
    }

    /// A point or directional light: no camera subpath reaches it.
    pub fn is_delta_light(&self) -> bool {
        matches!(self.kind, VertexKind::PointLight { .. } | VertexKind::DirectionalLight { .. })
    }

    /// Area density (m^-2) of the point itself when a light sampler picks it (a directional
    /// light's: on its disk, which cancels in every ratio of strategies' densities).
    pub fn light_origin_pdf(&self) -> f32 {
        match self.kind {
            VertexKind::AreaLight { origin_pdf } => origin_pdf,
            VertexKind::PointLight { select_pdf } => select_pdf,
            VertexKind::DirectionalLight { select_pdf, beam_area } => select_pdf / beam_area,
            _ => 0.0,
        }
    }
}

/// `solid_angle_to_area` of subpath.wesl.
fn solid_angle_to_area(pdf_dir: f32, origin: Vec3, to: &Vertex) -> f32 {
    let d = to.position - origin;
    let dist2 = d.length_squared();
    if dist2 <= 0.0 {
        return 0.0;
    }
    let mut pdf = pdf_dir / dist2;
    if to.has_area_measure() {
        pdf *= to.normal.dot(d).abs() / dist2.sqrt();
    }
    pdf
}

/// `vertex_pdf` of subpath.wesl: the area density at `next` with which `v` samples it, having
/// been reached from `prev` (ignored by the camera and lights).
pub fn vertex_pdf(v: &Vertex, prev: Option<&Vertex>, next: &Vertex) -> f32 {
    let w = (next.position - v.position).normalize();
    if let VertexKind::DirectionalLight { beam_area, .. } = v.kind {
        // A planar density across the beam, times the cosine at `next`.
        let cos = if next.has_area_measure() { next.normal.dot(v.normal).abs() } else { 1.0 };
        return cos / beam_area;
    }
    let pdf_dir = match v.kind {
        VertexKind::Camera { image_area } => {
            let c = w.dot(v.normal);
            if c <= 0.0 { 0.0 } else { 1.0 / (image_area * c * c * c) }
        }
        VertexKind::AreaLight { .. } => w.dot(v.normal).max(0.0) * FRAC_1_PI,
        VertexKind::PointLight { .. } => 0.25 * FRAC_1_PI,
        VertexKind::DirectionalLight { .. } => unreachable!("returned above"),
        VertexKind::Medium { g, .. } => {
            let prev = prev.expect("a medium vertex has a predecessor");
            crate::scene::medium::hg_phase((v.position - prev.position).normalize().dot(w), g)
        }
        VertexKind::Surface(bsdf) => {
            if w.dot(v.normal) <= 0.0 {
                return 0.0;
            }
            let prev = prev.expect("a surface vertex has a predecessor");
            let frame = Frame::from_normal(v.normal);
            let wo = frame.to_local((prev.position - v.position).normalize());
            bsdf.pdf(wo, frame.to_local(w))
        }
    };
    solid_angle_to_area(pdf_dir, v.position, next)
}

/// A subpath vertex as the kernels store it: the vertex and its two area densities.
#[derive(Clone, Copy, Debug)]
struct Stored {
    vertex: Vertex,
    pdf_fwd: f32,
    pdf_rev: f32,
}

/// The subpath `vertices` (in sampling order, vertex 0 the pinhole or the light) with the
/// densities generate_subpaths and extend_subpaths store: pdf_fwd of each step, and pdf_rev of
/// vertex i set when vertex i + 1 samples its continuation (so the last two have none).
fn stored_subpath(vertices: &[Vertex]) -> Vec<Stored> {
    let mut out: Vec<Stored> = Vec::with_capacity(vertices.len());
    for (i, v) in vertices.iter().enumerate() {
        let pdf_fwd = match i {
            0 => match v.kind {
                VertexKind::Camera { .. } => 1.0,
                _ => v.light_origin_pdf(),
            },
            _ => vertex_pdf(&vertices[i - 1], i.checked_sub(2).map(|j| &vertices[j]), v),
        };
        out.push(Stored { vertex: *v, pdf_fwd, pdf_rev: 0.0 });
        if i >= 2 {
            // Vertex i - 1 sampled vertex i: it also sets the reverse density of vertex i - 2.
            out[i - 2].pdf_rev = vertex_pdf(&vertices[i - 1], Some(v), &vertices[i - 2]);
        }
    }
    out
}

fn remap0(x: f32) -> f32 {
    if x != 0.0 { x } else { 1.0 }
}

/// The power-heuristic weight of strategy (s, t = path.len() - s) for `path` (x_0 on a light,
/// the last vertex the pinhole), as `connect_direct` computes it (term by term here; the kernel
/// takes the ratios away from the connection from per-slot sums, docs/design.md section 4.2):
/// strategies whose connection would end at a delta vertex are left out, and the zero densities that mark delta steps count
/// as 1 (PBRT's BDPT). Only for strategies that can sample the path (neither x_{s-1} nor x_s
/// a delta vertex).
pub fn mis_weight(path: &[Vertex], s: usize) -> f32 {
    let k = path.len();
    let t = k - s;
    assert!(t >= 1 && k >= 2);
    let light = stored_subpath(&path[..s]);
    let camera_order: Vec<Vertex> = path[s..].iter().rev().copied().collect();
    let camera = stored_subpath(&camera_order);
    let pt = &camera[t - 1].vertex;
    let ptm = (t >= 2).then(|| camera[t - 2].vertex);
    let qs = (s >= 1).then(|| light[s - 1].vertex);
    let qsm = (s >= 2).then(|| light[s - 2].vertex);
    // The densities the connection implies for its four neighbours.
    let (pt_rev, ptm_rev, qs_rev, qsm_rev) = match qs {
        None => {
            // s = 0: pt lies on a light; it and ptm are reached from the light's side.
            let ptm = ptm.expect("s = 0 needs t >= 2");
            (pt.light_origin_pdf(), vertex_pdf(pt, None, &ptm), 0.0, 0.0)
        }
        Some(qs) => (
            vertex_pdf(&qs, qsm.as_ref(), pt),
            ptm.map_or(0.0, |m| vertex_pdf(pt, Some(&qs), &m)),
            vertex_pdf(pt, ptm.as_ref(), &qs),
            qsm.map_or(0.0, |m| vertex_pdf(&qs, Some(pt), &m)),
        ),
    };
    let mut sum = 0.0;
    let mut ri = 1.0;
    for i in (1..t).rev() {
        let rev = if i == t - 1 {
            pt_rev
        } else if i + 2 == t {
            ptm_rev
        } else {
            camera[i].pdf_rev
        };
        ri *= remap0(rev) / remap0(camera[i].pdf_fwd);
        if !(camera[i].vertex.is_delta() || camera[i - 1].vertex.is_delta()) {
            sum += ri * ri;
        }
    }
    ri = 1.0;
    for i in (0..s).rev() {
        let rev = if i + 1 == s {
            qs_rev
        } else if i + 2 == s {
            qsm_rev
        } else {
            light[i].pdf_rev
        };
        ri *= remap0(rev) / remap0(light[i].pdf_fwd);
        let connectible = match i {
            0 => !light[0].vertex.is_delta_light(),
            _ => !(light[i].vertex.is_delta() || light[i - 1].vertex.is_delta()),
        };
        if connectible {
            sum += ri * ri;
        }
    }
    1.0 / (1.0 + sum)
}

/// The paper's approximate MIS weight of an ellipsoidal vertex at x_e = path[e] (1 <= e <=
/// k - 2), computed as `ellipsoidal_mis_weight` in ellipsoidal_mis.wesl does: with p_j the
/// density of the path sampled by a direct connection across edge (x_{j-1}, x_j),
/// w_e = (p_e + p_{e+1}) / 2 / sum_{j=1}^{k-1} c_j p_j (c_1 = c_{k-1} = 1/2, else 1), from ratios
/// to p_e of each vertex's light-side and camera-side densities, using the densities the
/// subpaths store and those the connection computes next to x_e. With a directional light,
/// e = 1 is the weight of the next-event connection from camera vertex x_1 to the light, which
/// takes the place of the spheroid next to it. With delta vertices, c_j counts only the
/// vertices a spheroid can place ([`spheroid_places`]), and delta steps' zero densities count
/// as 1. (The kernels also bar vertices inside a medium, which this twin's vertices do not
/// model.)
pub fn ellipsoidal_mis_weight(path: &[Vertex], e: usize) -> f32 {
    let k = path.len();
    assert!(e >= 1 && e + 2 <= k);
    let (s, t) = (e, k - 1 - e);
    let light = stored_subpath(&path[..s]);
    let camera_order: Vec<Vertex> = path[e + 1..].iter().rev().copied().collect();
    let camera = stored_subpath(&camera_order);
    let (qs, pt, xe) = (&path[s - 1], &path[e + 1], &path[e]);
    let qsm = (s >= 2).then(|| path[s - 2]);
    let ptm = (t >= 2).then(|| path[e + 2]);
    let delta: Vec<bool> = path.iter().map(Vertex::is_delta).collect();
    let c = |j: usize| spheroid_edge_share(path, j);
    let mut sum = c(s);
    let mut r = 1.0f32;
    for j in (1..s).rev() {
        let pc = if j == s - 1 {
            vertex_pdf(xe, Some(pt), qs)
        } else if j + 2 == s {
            vertex_pdf(qs, Some(xe), qsm.as_ref().unwrap())
        } else {
            light[j].pdf_rev
        };
        let pc = if delta[j + 1] { 1.0 } else { pc };
        let pl = if delta[j - 1] { 1.0 } else { light[j].pdf_fwd.max(1e-30) };
        r *= pc / pl;
        sum += c(j) * r;
    }
    r = vertex_pdf(qs, qsm.as_ref(), xe) / vertex_pdf(pt, ptm.as_ref(), xe).max(1e-30);
    let r_next = r;
    sum += c(s + 1) * r;
    for j in s + 1..=k - 2 {
        let i = t + s - j;
        let pl = if i == t - 1 {
            vertex_pdf(xe, Some(qs), pt)
        } else if i + 2 == t {
            vertex_pdf(pt, Some(xe), ptm.as_ref().unwrap())
        } else {
            camera[i].pdf_rev
        };
        let pl = if delta[j - 1] { 1.0 } else { pl };
        let pc = if delta[j + 1] { 1.0 } else { camera[i].pdf_fwd.max(1e-30) };
        r *= pl / pc;
        sum += c(j + 1) * r;
    }
    0.5 * (1.0 + r_next) / sum
}

/// Whether a spheroid can place vertex m of `path` (ellipsoidal_mis.wesl `spheroid_places`):
/// 1 <= m <= k - 2, and neither it nor a neighbour is a delta vertex.
pub fn spheroid_places(path: &[Vertex], m: usize) -> bool {
    (1..=path.len().saturating_sub(2)).contains(&m) && !path[m - 1..=m + 1].iter().any(Vertex::is_delta)
}

/// c_j of edge j >= 1 (between x_{j-1} and x_j) in the paper's weights: half for each of its two
/// ends a spheroid can place (1/2 at the ends of a path without delta vertices, 1 between).
fn spheroid_edge_share(path: &[Vertex], j: usize) -> f32 {
    0.5 * (f32::from(u8::from(spheroid_places(path, j - 1))) + f32::from(u8::from(spheroid_places(path, j))))
}

/// `spheroid_vertex_density` of family_mis.wesl: the area density (m^-2) the families' weights
/// give a spheroid's vertex at `x` (unit normal `normal`) between `prev` and `next`, with
/// target-length density `p_tau` (m^-1) at the path's length: p_tau |grad_S L| / (2 pi b), b
/// the spheroid's semi-minor axis; zero within the needle guard (`needle_guard`, relative).
pub fn spheroid_vertex_density(prev: Vec3, x: Vec3, normal: Vec3, next: Vec3, p_tau: f32, needle_guard: f32) -> f32 {
    let (d1, d2, d) = (x.distance(prev), x.distance(next), prev.distance(next));
    let tau_e = d1 + d2;
    if !(d1 > 0.0 && d2 > 0.0 && tau_e > d * (1.0 + needle_guard)) {
        return 0.0;
    }
    let g = (x - prev) / d1 + (x - next) / d2;
    let along_surface = (g - g.dot(normal) * normal).length();
    let b = 0.5 * ((tau_e - d) * (tau_e + d)).sqrt();
    p_tau * along_surface / (std::f32::consts::TAU * b)
}

/// `medium_vertex_density` of family_mis.wesl: the density (m^-3, over the extinction) the
/// families' weights give vertex `i` of `path`, in a participating medium, when a spheroid
/// places it: connect_medium's density of placing it (`spheroid_point_mixture` of medium.wesl:
/// half uniform in prolate spheroidal coordinates, a quarter along a ray from each neighbour,
/// in a direction uniform over the half-space a surface reflects into or over the sphere from a
/// medium vertex; from the light 1 / 2 pi for an area light and 1 / 4 pi for a point light;
/// from the pinhole the camera's own density) times the target-length density `p_tau` (m^-1),
/// over the extinction there, which the subpaths' densities leave out; zero within the needle
/// guard (`needle_guard`, relative), where no spheroid is queried.
pub fn medium_vertex_density(path: &[Vertex], i: usize, p_tau: f32, needle_guard: f32) -> f32 {
    use std::f32::consts::PI;
    let (prev, v, next) = (&path[i - 1], &path[i], &path[i + 1]);
    let VertexKind::Medium { sigma_t, .. } = v.kind else { panic!("vertex {i} is not in a medium") };
    let (d1, d2) = (v.position.distance(prev.position), v.position.distance(next.position));
    if !(d1 > 0.0 && d2 > 0.0 && d1 + d2 > prev.position.distance(next.position) * (1.0 + needle_guard)) {
        return 0.0;
    }
    let ray = |u: &Vertex| match u.kind {
        VertexKind::Medium { .. } | VertexKind::PointLight { .. } => 0.25 / PI,
        _ => 0.5 / PI,
    };
    let from_next = match next.kind {
        VertexKind::Camera { .. } => vertex_pdf(next, None, v),
        _ => ray(next) / (d2 * d2),
    };
    let sum = (prev.position - v.position) / d1 + (next.position - v.position) / d2;
    let q = 0.5 / (2.0 * PI * d1 * d2) + 0.25 * (ray(prev) / (d1 * d1) + from_next) * 0.5 * sum.dot(sum);
    p_tau * q / sigma_t.max(1e-30)
}

/// `combined_weight` of family_mis.wesl: the weight of a combined render's contribution through
/// `path` (x_0 on a light, the last vertex the pinhole), its family's share times its weight
/// within the family, for strategy `own` of `family` (direct: `own` light-subpath vertices,
/// weighted by the power heuristic; ellipsoidal: the vertex path[own] on a spheroid, weighted
/// by the paper's approximation). The direct family's share is S_D / (S_D + ratio S_E), S_D the
/// sum of the direct strategies' densities and S_E that of the spheroid vertices' stand-in
/// densities (`spheroid_vertex_density` or, in a medium, [`medium_vertex_density`] for the
/// placed vertex, the subpaths' densities for the rest), with target-length density `p_tau`
/// (m^-1) at the path's length, `ratio` ellipsoidal connections per direct one through surface
/// vertices and `medium_ratio` through medium vertices (paths of at least three vertices). Both sums leave
/// out what cannot sample the path (direct strategies ending at a delta vertex, vertices
/// [`spheroid_places`] rules out), and delta steps' zero densities count as 1.
pub fn combined_weight(
    path: &[Vertex],
    family: super::bidirectional::Family,
    own: usize,
    p_tau: f32,
    ratio: f32,
    medium_ratio: f32,
    needle_guard: f32,
) -> f32 {
    let k = path.len();
    assert!(k >= 3);
    let from_light = |i: usize| match i {
        0 => path[0].light_origin_pdf(),
        _ => vertex_pdf(&path[i - 1], i.checked_sub(2).map(|j| &path[j]), &path[i]),
    };
    // (The pinhole's density from the camera side is 1: it is never sampled.)
    let from_camera = |i: usize| if i + 1 < k { vertex_pdf(&path[i + 1], path.get(i + 2), &path[i]) } else { 1.0 };
    let first = if path[0].is_delta_light() { 1 } else { 0 };
    let (mut r, mut sd, mut sd2, mut sc, mut se, mut r_own, mut r_next) = (1.0f32, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
    let mut sm = 0.0f32;
    let delta: Vec<bool> = path.iter().map(Vertex::is_delta).collect();
    for j in first..k {
        if j == 0 || !(delta[j - 1] || delta[j]) {
            sd += r;
            sd2 += r * r;
        }
        if j >= 1 {
            sc += spheroid_edge_share(path, j) * r;
        }
        if j == own {
            r_own = r;
        }
        if j == own + 1 {
            r_next = r;
        }
        let camera = if j + 1 < k && delta[j + 1] { 1.0 } else { from_camera(j).max(1e-30) };
        let light = if j >= 1 && delta[j - 1] { 1.0 } else { from_light(j) };
        if spheroid_places(path, j) && p_tau > 0.0 && matches!(path[j].kind, VertexKind::Medium { .. }) {
            sm += r * medium_vertex_density(path, j, p_tau, needle_guard) / camera;
        } else if spheroid_places(path, j) && p_tau > 0.0 {
            let v = &path[j];
            let e = spheroid_vertex_density(
                path[j - 1].position,
                v.position,
                v.normal,
                path[j + 1].position,
                p_tau,
                needle_guard,
            );
            se += r * e / camera;
        }
        r *= (light / camera).min(1e8);
        if r > 1e10 || sd > 1e10 {
            let f = 1e-10;
            (r, sd, sd2, sc, se, r_own, r_next) = (r * f, sd * f, sd2 * f * f, sc * f, se * f, r_own * f, r_next * f);
            sm *= f;
        }
    }
    let share_d = sd / (sd + ratio * se + medium_ratio * sm);
    let w = match family {
        super::bidirectional::Family::Direct => share_d * (r_own * r_own / sd2),
        super::bidirectional::Family::Ellipsoidal => (1.0 - share_d) * (0.5 * (r_own + r_next) / sc),
    };
    if w.is_nan() { 0.0 } else { w.clamp(0.0, 1.0) }
}
