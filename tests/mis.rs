//! The multiple-importance weights of bidirectional path tracing (CPU twin of the kernels'
//! code): on random paths with Lambertian, glossy and plastic vertices, scattering vertices in
//! participating media (bidirectional weights), area, point and directional
//! lights, the weights of all strategies sum to one, and each equals the power heuristic
//! computed independently from the full path densities p_s = prod(light-side densities of
//! x_0..x_{s-1}) x prod(camera-side densities of x_s..x_{k-2}); likewise the paper's approximate
//! weights of ellipsoidal connections (with a directional light, e = 1 weighs the next-event
//! connection that replaces the spheroid next to the light); and the combined estimator's
//! weights of both families together. Paths may hold glass (delta) vertices: the strategies that
//! would connect at one are left out, no spheroid places one or a vertex next to one, and the
//! delta steps' densities count as 1 in every product (PBRT's convention, under which they
//! cancel between the strategies that remain).

mod common;

use gatetrace::integrator::mis::{Vertex, VertexKind, mis_weight, vertex_pdf};
use gatetrace::rng::Xorshift64Star;
use gatetrace::scene::Dielectric;
use gatetrace::scene::bsdf::{Bsdf, PlasticLobe};
use gatetrace::scene::plastic;
use glam::Vec3;

/// A plastic coat (GGX alpha 0.2, eta 1.5), whose sampling pdf depends on the direction it is
/// seen from through the coat's transmittance.
fn plastic_coat() -> PlasticLobe {
    static TABLE: std::sync::OnceLock<Vec<f64>> = std::sync::OnceLock::new();
    let table = TABLE.get_or_init(|| plastic::transmittance_table(0.2, 1.5));
    PlasticLobe {
        eta: 1.5,
        specular: 1.0,
        specular_weight: 0.6,
        transmittance: std::array::from_fn(|i| table[i] as f32),
    }
}

/// The kinds of light a random path starts on.
#[derive(Clone, Copy, PartialEq)]
enum Light {
    Area,
    Point,
    /// Travelling from the path's first point towards its second.
    Directional,
}

/// The light of trial `i`: point, directional, then two area lights in turn.
fn light_of_trial(i: usize) -> Light {
    [Light::Point, Light::Directional, Light::Area, Light::Area][i % 4]
}

/// A random path of `k` vertices: a light, k - 2 surfaces whose normals face both neighbours
/// (each glass, a delta vertex, with probability `glass`), and a pinhole looking roughly at its
/// neighbour.
fn random_path(rng: &mut Xorshift64Star, k: usize, light: Light, glass: f32) -> Vec<Vertex> {
    let positions: Vec<Vec3> = (0..k).map(|_| rng.next_vec3() * 2.0).collect();
    let mut path = Vec::with_capacity(k);
    for i in 0..k {
        let p = positions[i];
        let toward = |j: usize| (positions[j] - p).normalize();
        let vertex = if i == 0 {
            let (kind, normal) = match light {
                Light::Point => (VertexKind::PointLight { select_pdf: 0.3 + 0.7 * rng.next_f32() }, toward(1)),
                Light::Directional => {
                    let (select_pdf, beam_area) = (0.3 + 0.7 * rng.next_f32(), 5.0 + 20.0 * rng.next_f32());
                    (VertexKind::DirectionalLight { select_pdf, beam_area }, toward(1))
                }
                Light::Area => (VertexKind::AreaLight { origin_pdf: 0.5 + 3.0 * rng.next_f32() }, toward(1)),
            };
            // An area light's normal varies about the direction to x_1; a directional light's is
            // its direction of travel, exactly towards x_1.
            let normal =
                if light == Light::Directional { normal } else { (normal + 0.5 * rng.next_vec3()).normalize() };
            Vertex { kind, position: p, normal }
        } else if i == k - 1 {
            let image_area = 0.5 + rng.next_f32();
            Vertex {
                kind: VertexKind::Camera { image_area },
                position: p,
                normal: (toward(k - 2) + 0.3 * rng.next_vec3()).normalize(),
            }
        } else {
            let mut bsdf = Bsdf {
                base_color: Vec3::new(0.8, 0.5, 0.2),
                metallic: if rng.next_f32() < 0.4 { 0.0 } else { rng.next_f32() },
                alpha: 0.05 + 0.9 * rng.next_f32() * rng.next_f32(),
                plastic: None,
                dielectric: None,
                conductor_index: None,
            };
            if rng.next_f32() < 0.3 {
                bsdf = Bsdf { metallic: 0.0, alpha: 0.2, plastic: Some(plastic_coat()), ..bsdf };
            }
            if glass > 0.0 && rng.next_f32() < glass {
                let dielectric = Dielectric { eta: 1.5, specular: 1.0, thin: false, alpha: 0.0 };
                bsdf = Bsdf { metallic: 0.0, plastic: None, dielectric: Some(dielectric), ..bsdf };
            }
            let n = (toward(i - 1) + toward(i + 1) + 0.3 * rng.next_vec3()).normalize();
            Vertex { kind: VertexKind::Surface(bsdf), position: p, normal: n }
        };
        path.push(vertex);
    }
    path
}

/// `path` with each surface vertex turned, with probability `medium`, into a scattering vertex in
/// a participating medium (a random Henyey-Greenstein mean cosine in -0.8..0.8, an extinction
/// from 0.01 to 100 m^-1).
fn with_medium_vertices(rng: &mut Xorshift64Star, mut path: Vec<Vertex>, medium: f32) -> Vec<Vertex> {
    for v in &mut path {
        if matches!(v.kind, VertexKind::Surface(_)) && rng.next_f32() < medium {
            let g = 1.6 * rng.next_f32() - 0.8;
            v.kind = VertexKind::Medium { g, sigma_t: 10f32.powf(4.0 * rng.next_f32() - 2.0) };
        }
    }
    path
}

/// Whether every direction the path takes leaves each vertex on its normal's side (so every
/// density is nonzero and every strategy can sample it); a medium vertex has no side.
fn is_valid(path: &[Vertex]) -> bool {
    let k = path.len();
    (0..k).all(|i| {
        if matches!(path[i].kind, VertexKind::Medium { .. }) {
            return true;
        }
        let p = path[i].position;
        let ok = |j: usize| (path[j].position - p).dot(path[i].normal) > 1e-3 * (path[j].position - p).length();
        (i == 0 || ok(i - 1)) && (i == k - 1 || ok(i + 1))
    })
}

/// Whether strategy s (s light-side vertices) can sample the path: s = 0 needs an area light,
/// and no connection ends at a delta vertex.
fn connectible(path: &[Vertex], s: usize) -> bool {
    match s {
        0 => !path[0].is_delta_light(),
        _ => !(path[s - 1].is_delta() || path[s].is_delta()),
    }
}

/// p_s of the full path, computed directly: the light side generates x_0..x_{s-1} forwards, the
/// camera side x_{k-2}..x_s backwards (the pinhole x_{k-1} is not sampled); zero for a
/// strategy that cannot sample the path.
fn strategy_pdf(path: &[Vertex], s: usize) -> f64 {
    if !connectible(path, s) {
        return 0.0;
    }
    light_side_pdf(path, s) * camera_side_pdf(path, s)
}

/// The density with which the light side generates x_0..x_{n-1} (a step from a delta vertex
/// counting 1).
fn light_side_pdf(path: &[Vertex], n: usize) -> f64 {
    (0..n)
        .map(|i| match i {
            0 => path[0].light_origin_pdf() as f64,
            _ if path[i - 1].is_delta() => 1.0,
            _ => vertex_pdf(&path[i - 1], i.checked_sub(2).map(|j| &path[j]), &path[i]) as f64,
        })
        .product()
}

/// The density with which the camera side generates x_{k-2}..x_from backwards (a step from a
/// delta vertex counting 1).
fn camera_side_pdf(path: &[Vertex], from: usize) -> f64 {
    (from..path.len() - 1)
        .map(|i| if path[i + 1].is_delta() { 1.0 } else { vertex_pdf(&path[i + 1], path.get(i + 2), &path[i]) as f64 })
        .product()
}

/// c_j of edge j in the paper's weights: half for each end of the edge a spheroid can place.
fn edge_share(path: &[Vertex], j: usize) -> f64 {
    use gatetrace::integrator::mis::spheroid_places;
    0.5 * (spheroid_places(path, j - 1) as u8 + spheroid_places(path, j) as u8) as f64
}

#[test]
fn weights_of_all_strategies_sum_to_one_and_match_the_power_heuristic() {
    let mut rng = Xorshift64Star(0x9E3779B97F4A7C15);
    let mut checked = 0;
    for trial in 0..4000 {
        let k = 2 + trial % 6;
        let light = light_of_trial(trial);
        let path = random_path(&mut rng, k, light, 0.25);
        let path = with_medium_vertices(&mut rng, path, 0.3);
        if !is_valid(&path) {
            continue;
        }
        let strategies = (0..k).filter(|&s| connectible(&path, s));
        let pdfs: Vec<f64> = (0..k).map(|s| strategy_pdf(&path, s)).collect();
        let norm: f64 = pdfs.iter().map(|p| p * p).sum();
        if !(norm.is_finite() && norm > 0.0) {
            continue;
        }
        let mut sum = 0.0f64;
        for s in strategies {
            let w = mis_weight(&path, s) as f64;
            let expected = pdfs[s] * pdfs[s] / norm;
            assert!(
                (w - expected).abs() <= 1e-3 * expected.max(1e-3),
                "path of {k} vertices, strategy s = {s}: weight {w}, power heuristic {expected} (pdfs {pdfs:?})"
            );
            sum += w;
        }
        assert!((sum - 1.0).abs() < 1e-4, "path of {k} vertices: weights sum to {sum}");
        checked += 1;
    }
    assert!(checked > 1000, "only {checked} valid random paths");
    println!("{checked} random paths checked");
}

/// The paper's approximate weights of ellipsoidal connections (ellipsoidal_mis.wesl, CPU twin
/// `ellipsoidal_mis_weight`) match their definition, (p_e + p_{e+1}) / 2 over the sum of c_j p_j
/// with p_j the explicit products of `strategy_pdf`, and sum to one over the placeable vertices
/// of random paths, on surfaces and in media (connect_medium places the latter).
#[test]
fn approximate_ellipsoidal_weights_match_their_definition_and_sum_to_one() {
    use gatetrace::integrator::mis::{ellipsoidal_mis_weight, spheroid_places};
    let mut rng = Xorshift64Star(0x1234_5678_9ABC_DEF1);
    let mut checked = 0;
    for trial in 0..4000 {
        let k = 3 + trial % 5;
        let path = random_path(&mut rng, k, light_of_trial(trial), 0.2);
        // Half the paths scatter in media too: a spheroid places a vertex in a medium as one on a
        // surface (connect_medium).
        let path = if trial % 2 == 1 { with_medium_vertices(&mut rng, path, 0.4) } else { path };
        if !is_valid(&path) {
            continue;
        }
        let pdfs: Vec<f64> = (0..k).map(|s| strategy_pdf(&path, s)).collect();
        let norm: f64 = (1..k).map(|j| edge_share(&path, j) * pdfs[j]).sum();
        if !(norm.is_finite() && norm > 0.0) {
            continue;
        }
        let mut sum = 0.0f64;
        for e in (1..=k - 2).filter(|&e| spheroid_places(&path, e)) {
            let w = ellipsoidal_mis_weight(&path, e) as f64;
            let expected = 0.5 * (pdfs[e] + pdfs[e + 1]) / norm;
            assert!(
                (w - expected).abs() <= 1e-3 * expected.max(1e-3),
                "path of {k} vertices, ellipsoidal vertex {e}: weight {w}, definition {expected}"
            );
            sum += w;
        }
        assert!((sum - 1.0).abs() < 1e-4, "path of {k} vertices: weights sum to {sum}");
        checked += 1;
    }
    assert!(checked > 1000, "only {checked} valid random paths");
}

/// The random path of trial `trial` of the combined weights' tests (3 to 8 vertices, area and
/// point lights: a combined render refuses directional ones; glass vertices with probability
/// `glass`; in every other trial, vertices in a medium with probability 0.4), if its directions
/// leave each vertex on its normal's side.
fn combined_trial_path(rng: &mut Xorshift64Star, trial: usize, glass: f32) -> Option<(Vec<Vertex>, Light)> {
    let light = if trial.is_multiple_of(3) { Light::Point } else { Light::Area };
    let path = random_path(rng, 3 + trial % 6, light, glass);
    let path = if trial % 4 >= 2 { with_medium_vertices(rng, path, 0.4) } else { path };
    is_valid(&path).then_some((path, light))
}

/// Whether vertex i of `path` lies in a participating medium.
fn in_medium(path: &[Vertex], i: usize) -> bool {
    matches!(path[i].kind, VertexKind::Medium { .. })
}

/// The combined estimator's weights (family_mis.wesl `combined_weight`, CPU twin of the same
/// name): each direct strategy's weight is the direct family's share times its power-heuristic
/// weight, each spheroid vertex's the ellipsoidal family's share times the paper's weight, the
/// share S_D / (S_D + R S_E + R_m S_M) computed here from explicit products (S_D the sum of the
/// direct strategies' densities, S_E and S_M those of the spheroid vertices' on surfaces and in
/// media: the light-side densities of x_0..x_{m-1} times e(x_m) times the camera-side ones of
/// x_{m+1}..x_{k-2}, R and R_m = R / K the connections per direct one of each); and the weights
/// of all strategies of both families sum to one, on paths with vertices in media too.
#[test]
fn combined_weights_match_their_definition_and_sum_to_one() {
    use gatetrace::integrator::combined::Family;
    use gatetrace::integrator::mis::{
        combined_weight, medium_vertex_density, spheroid_places, spheroid_vertex_density,
    };
    let mut rng = Xorshift64Star(0x0DDB_1A5E_5BAD_5EED);
    let (mut checked, mut media) = (0, 0);
    let mut shares = Vec::new();
    for trial in 0..4000 {
        let Some((path, _)) = combined_trial_path(&mut rng, trial, 0.2) else { continue };
        let k = path.len();
        // Target densities from those of a 1 mm gate (1000 m^-1) to a 10 m one's, 1 to 8
        // ellipsoidal connections per direct one.
        let p_tau = 10f32.powf(3.0 - 4.0 * rng.next_f32());
        let connections = 1 + (rng.next_f32() * 8.0) as u32;
        let medium_ratio = 2f32.powf(6.0 * rng.next_f32() - 3.0);
        let ratio = connections as f32 * medium_ratio;
        let pdfs: Vec<f64> = (0..k).map(|s| strategy_pdf(&path, s)).collect();
        let sd: f64 = pdfs.iter().sum();
        let sd2: f64 = pdfs.iter().map(|p| p * p).sum();
        let sc: f64 = (1..k).map(|j| edge_share(&path, j) * pdfs[j]).sum();
        let (mut se, mut sm) = (0.0f64, 0.0f64);
        for m in (1..=k - 2).filter(|&m| spheroid_places(&path, m)) {
            let v = &path[m];
            let rest = light_side_pdf(&path, m) * camera_side_pdf(&path, m + 1);
            if in_medium(&path, m) {
                sm += rest * medium_vertex_density(&path, m, p_tau, 1e-6) as f64;
            } else {
                let e = spheroid_vertex_density(
                    path[m - 1].position,
                    v.position,
                    v.normal,
                    path[m + 1].position,
                    p_tau,
                    1e-6,
                );
                se += rest * e as f64;
            }
        }
        let share = sd / (sd + ratio as f64 * se + medium_ratio as f64 * sm);
        if !(share.is_finite() && sd2.is_finite() && sd > 0.0) {
            continue;
        }
        let close = |w: f64, expected: f64| (w - expected).abs() <= 1e-3 * expected.max(1e-3);
        let mut sum = 0.0f64;
        for s in (0..k).filter(|&s| connectible(&path, s)) {
            let w = combined_weight(&path, Family::Direct, s, p_tau, ratio, medium_ratio, 1e-6) as f64;
            let expected = share * pdfs[s] * pdfs[s] / sd2;
            assert!(close(w, expected), "path of {k} vertices, direct s = {s}: weight {w}, definition {expected}");
            sum += w;
        }
        for e in (1..=k - 2).filter(|&e| spheroid_places(&path, e)) {
            let w = combined_weight(&path, Family::Ellipsoidal, e, p_tau, ratio, medium_ratio, 1e-6) as f64;
            let expected = (1.0 - share) * 0.5 * (pdfs[e] + pdfs[e + 1]) / sc;
            assert!(close(w, expected), "path of {k} vertices, spheroid vertex {e}: weight {w}, definition {expected}");
            sum += w;
        }
        assert!((sum - 1.0).abs() < 1e-4, "path of {k} vertices: the weights of both families sum to {sum}");
        shares.push(share);
        media += usize::from(sm > 0.0);
        checked += 1;
    }
    assert!(checked > 1000, "only {checked} valid random paths");
    // Both families carry weight on these paths: the test sees shares away from 0 and 1.
    let between = shares.iter().filter(|&&s| s > 0.01 && s < 0.99).count();
    assert!(between > checked / 10, "only {between} of {checked} paths share their weight between the families");
    assert!(media > checked / 10, "only {media} of {checked} paths had a medium vertex a spheroid places");
}

/// `combined_weight` of family_mis.wesl (probe_functions 20) against its twin on random paths and
/// family ratios (paths with glass vertices among them): the same densities and delta vertices
/// in, the same weights out, with the target-length density of a box gate's table (checked
/// against the CPU sampler's).
#[test]
fn combined_weights_in_wgsl_match_the_twin() {
    use gatetrace::film::Gate;
    use gatetrace::integrator::combined::Family;
    use gatetrace::integrator::mis::{combined_weight, spheroid_places};
    use gatetrace::integrator::{PathTracer, RenderSettings, target_sampler};
    // COMBINED_RECORDS: a header, two records per vertex (k <= 8), two of extinctions, the ratios.
    const RECORDS: usize = 20;
    let ctx = common::gpu();
    let scene = common::cornell_box();
    let gate = Gate::Box { start: 3.0, end: 3.3 };
    let settings = RenderSettings { width: 4, height: 4, max_bounces: 5, gate, ..Default::default() };
    let tracer = PathTracer::new(ctx, &scene, &settings).unwrap();
    let sampler = target_sampler(&scene, &settings).unwrap();
    let mut rng = Xorshift64Star(0xC0FF_EE00_1234_5678);
    let (mut input, mut cases) = (Vec::new(), Vec::new());
    for trial in 0..2000 {
        let Some((path, light)) = combined_trial_path(&mut rng, trial, 0.2) else { continue };
        let k = path.len();
        let placed: Vec<usize> = (1..=k - 2).filter(|&e| spheroid_places(&path, e)).collect();
        let connected: Vec<usize> = (0..k).filter(|&s| connectible(&path, s)).collect();
        let (length, inv_p) = sampler.sample(rng.next_f32());
        let pick = |of: &[usize], u: f32| of[((u * of.len() as f32) as usize).min(of.len() - 1)];
        let u = rng.next_f32();
        let (family, own) = if trial % 2 == 0 || placed.is_empty() {
            if connected.is_empty() {
                continue;
            }
            (Family::Direct, pick(&connected, u))
        } else {
            (Family::Ellipsoidal, pick(&placed, u))
        };
        // The family, 4 for an area light, 8 times the bits of the delta vertices, 2048 times
        // those of the vertices in a medium.
        let deltas: u32 = path.iter().enumerate().map(|(i, v)| u32::from(v.is_delta()) << i).sum();
        let media: u32 = (0..k).map(|i| u32::from(in_medium(&path, i)) << i).sum();
        let code = family as u32 + if light == Light::Area { 4 } else { 0 } + 8 * deltas + 2048 * media;
        input.push([k as f32, own as f32, code as f32, length]);
        for (i, v) in path.iter().enumerate() {
            let from_light = match i {
                0 => v.light_origin_pdf(),
                _ => vertex_pdf(&path[i - 1], i.checked_sub(2).map(|j| &path[j]), v),
            };
            let from_camera = if i + 1 < k { vertex_pdf(&path[i + 1], path.get(i + 2), v) } else { 1.0 };
            input.push([v.position.x, v.position.y, v.position.z, from_light]);
            input.push([v.normal.x, v.normal.y, v.normal.z, from_camera]);
        }
        // The extinctions, in two records.
        let mut sigma_t = [0.0f32; 8];
        for (i, v) in path.iter().enumerate() {
            if let VertexKind::Medium { sigma_t: s, .. } = v.kind {
                sigma_t[i] = s;
            }
        }
        input.resize((cases.len() + 1) * RECORDS - 3, [0.0; 4]);
        input.push([sigma_t[0], sigma_t[1], sigma_t[2], sigma_t[3]]);
        input.push([sigma_t[4], sigma_t[5], sigma_t[6], sigma_t[7]]);
        // The ratios of a combined render: R = K (1 to 8) times the ellipsoidal half's share
        // (1/8 to 8), and R / K.
        let connections = (1 + (rng.next_f32() * 8.0) as u32) as f32;
        let medium_ratio = 2f32.powf(6.0 * rng.next_f32() - 3.0);
        let ratio = connections * medium_ratio;
        input.push([ratio, medium_ratio, 0.0, 0.0]);
        cases.push((path, family, own, 1.0 / inv_p, ratio, medium_ratio));
    }
    assert!(cases.len() > 500, "only {} valid random paths", cases.len());
    assert!(cases.iter().any(|c| c.0.iter().any(Vertex::is_delta)), "some paths hold glass");
    let placed_in_media = cases.iter().filter(|c| (1..c.0.len() - 1).any(|m| in_medium(&c.0, m))).count();
    assert!(placed_in_media > cases.len() / 10, "only {placed_in_media} paths have vertices in a medium");
    let extra = [("FUNCTION", 20.0), ("HAS_DIELECTRIC", 1.0), ("HAS_MEDIA", 1.0)];
    let out = common::run_probe(ctx, &tracer, "probe_functions", &extra, &input, cases.len());
    for (i, ((path, family, own, p_tau, ratio, medium_ratio), o)) in cases.iter().zip(&out).enumerate() {
        assert!((o[1] - p_tau).abs() <= 1e-4 * p_tau, "path {i}: target density GPU {} CPU {p_tau}", o[1]);
        let twin = combined_weight(path, *family, *own, o[1], *ratio, *medium_ratio, 1e-6);
        assert!(
            (o[0] - twin).abs() <= 1e-3 * twin.max(1e-3),
            "path {i} ({} vertices, {family:?} {own}): weight GPU {} CPU {twin}",
            path.len(),
            o[0]
        );
    }
    let between = out.iter().filter(|o| o[0] > 0.01 && o[0] < 0.99).count();
    assert!(between > cases.len() / 4, "only {between} of {} weights lie between 0.01 and 0.99", cases.len());
}
