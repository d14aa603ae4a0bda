//! Deterministic integrals over triangles for references independent of the renderer: a
//! 7-point rule, and the part of a planar convex polygon that a point sees past other polygons
//! (central projections of the occluders onto its plane, cut away by convex differences).

use glam::{DVec2, DVec3};

use super::stats::{sidak, t_critical};

/// Points of the 7-point Dunavant rule on a triangle (degree 5): barycentric coordinates and
/// weights, summing to 1.
pub const DUNAVANT: [([f64; 3], f64); 7] = {
    const A1: f64 = 0.059_715_871_789_770;
    const B1: f64 = 0.470_142_064_105_115;
    const A2: f64 = 0.797_426_985_353_087;
    const B2: f64 = 0.101_286_507_323_456;
    const W1: f64 = 0.132_394_152_788_506;
    const W2: f64 = 0.125_939_180_544_827;
    [
        ([1.0 / 3.0, 1.0 / 3.0, 1.0 / 3.0], 0.225),
        ([A1, B1, B1], W1),
        ([B1, A1, B1], W1),
        ([B1, B1, A1], W1),
        ([A2, B2, B2], W2),
        ([B2, A2, B2], W2),
        ([B2, B2, A2], W2),
    ]
};

/// The integral of `f` over triangle `v` by the Dunavant rule on each of its 4^`levels`
/// congruent pieces.
pub fn triangle_integral(v: [DVec3; 3], levels: u32, f: &mut dyn FnMut(DVec3) -> f64) -> f64 {
    if levels > 0 {
        let (ab, bc, ca) = ((v[0] + v[1]) / 2.0, (v[1] + v[2]) / 2.0, (v[2] + v[0]) / 2.0);
        return [[v[0], ab, ca], [ab, v[1], bc], [ca, bc, v[2]], [ab, bc, ca]]
            .into_iter()
            .map(|piece| triangle_integral(piece, levels - 1, f))
            .sum();
    }
    let area = 0.5 * (v[1] - v[0]).cross(v[2] - v[0]).length();
    DUNAVANT.iter().map(|&(b, w)| w * f(b[0] * v[0] + b[1] * v[1] + b[2] * v[2])).sum::<f64>() * area
}

/// The part of convex polygon `poly` where a . x <= b.
fn clip_half_plane(poly: &[DVec2], a: DVec2, b: f64) -> Vec<DVec2> {
    let mut out = Vec::new();
    for (i, &p) in poly.iter().enumerate() {
        let q = poly[(i + 1) % poly.len()];
        let (fp, fq) = (a.dot(p) - b, a.dot(q) - b);
        if fp <= 0.0 {
            out.push(p);
        }
        if (fp < 0.0 && fq > 0.0) || (fq < 0.0 && fp > 0.0) {
            out.push(p + (q - p) * (fp / (fp - fq)));
        }
    }
    out
}

/// Twice the signed area of a polygon (positive counter-clockwise).
fn signed_area2(poly: &[DVec2]) -> f64 {
    (0..poly.len()).map(|i| poly[i].perp_dot(poly[(i + 1) % poly.len()])).sum()
}

/// Convex polygon `a` less convex polygon `s` (counter-clockwise): convex pieces.
fn difference(a: &[DVec2], s: &[DVec2]) -> Vec<Vec<DVec2>> {
    let mut pieces = Vec::new();
    let mut rest = a.to_vec();
    for (i, &p) in s.iter().enumerate() {
        let e = s[(i + 1) % s.len()] - p;
        let outward = DVec2::new(e.y, -e.x);
        let outside = clip_half_plane(&rest, -outward, -outward.dot(p));
        if outside.len() >= 3 && signed_area2(&outside).abs() > 1e-24 {
            pieces.push(outside);
        }
        rest = clip_half_plane(&rest, outward, outward.dot(p));
        if rest.len() < 3 {
            break;
        }
    }
    pieces
}

/// The part of 3D polygon `poly` where lo < n . (x - c) < hi.
fn clip_slab(poly: &[DVec3], n: DVec3, c: DVec3, lo: f64, hi: f64) -> Vec<DVec3> {
    let clip = |poly: &[DVec3], f: &dyn Fn(DVec3) -> f64| {
        let mut out = Vec::new();
        for (i, &p) in poly.iter().enumerate() {
            let q = poly[(i + 1) % poly.len()];
            let (fp, fq) = (f(p), f(q));
            if fp <= 0.0 {
                out.push(p);
            }
            if (fp < 0.0 && fq > 0.0) || (fq < 0.0 && fp > 0.0) {
                out.push(p + (q - p) * (fp / (fp - fq)));
            }
        }
        out
    };
    let above = clip(poly, &|x| lo - n.dot(x - c));
    if above.len() < 3 {
        return above;
    }
    clip(&above, &|x| n.dot(x - c) - hi)
}

/// The triangles (a fan of each convex piece) covering the part of triangle `face` that point
/// `p` sees past the triangles `occluders` (the face itself among them is skipped, as is any
/// occluder in its plane): each occluder's part between p and the face's plane, projected from
/// p onto that plane, is cut away. Empty when p lies in or behind the face's plane.
pub fn visible_part(face: [DVec3; 3], occluders: &[[DVec3; 3]], p: DVec3) -> Vec<[DVec3; 3]> {
    let c = face[0];
    let n = (face[1] - face[0]).cross(face[2] - face[0]).normalize();
    let height = n.dot(p - c);
    if !(height > 0.0) {
        return Vec::new();
    }
    let u = (face[1] - face[0]).normalize();
    let v = n.cross(u);
    let flat = |x: DVec3| DVec2::new((x - c).dot(u), (x - c).dot(v));
    let counter_clockwise = |mut poly: Vec<DVec2>| {
        if signed_area2(&poly) < 0.0 {
            poly.reverse();
        }
        poly
    };
    let mut pieces = vec![counter_clockwise(face.map(flat).to_vec())];
    for occluder in occluders {
        if *occluder == face {
            continue;
        }
        let between = clip_slab(occluder, n, c, 1e-12, height - 1e-12);
        if between.len() < 3 {
            continue;
        }
        let shadow: Vec<DVec2> =
            between.iter().map(|&x| flat(p + (x - p) * (height / (height - n.dot(x - c))))).collect();
        if signed_area2(&shadow).abs() < 1e-24 {
            continue;
        }
        let shadow = counter_clockwise(shadow);
        pieces = pieces.iter().flat_map(|piece| difference(piece, &shadow)).collect();
    }
    let lift = |q: DVec2| c + q.x * u + q.y * v;
    pieces
        .iter()
        .flat_map(|piece| (1..piece.len() - 1).map(|i| [lift(piece[0]), lift(piece[i]), lift(piece[i + 1])]))
        .collect()
}

/// Asserts that each point's total over the bins and channels of `films` (batches of one
/// capture, point-major) matches `reference` (one total per point), and so does their sum:
/// Student's t over the batches, Sidak's correction over the points and the sum at family-wise
/// `alpha`. Prints the sum's comparison under `name`.
pub fn assert_point_totals_match(name: &str, films: &[gatetrace::film::Film], reference: &[f64], alpha: f64) {
    let points = reference.len();
    let totals: Vec<Vec<f64>> = films
        .iter()
        .map(|film| film.data.chunks(film.data.len() / points).map(|p| p.iter().map(|&x| x as f64).sum()).collect())
        .collect();
    let n = films.len() as f64;
    let stats = |value: &dyn Fn(&Vec<f64>) -> f64| {
        let v: Vec<f64> = totals.iter().map(value).collect();
        let mean = v.iter().sum::<f64>() / n;
        (mean, v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / ((n - 1.0) * n))
    };
    let limit = t_critical(sidak(alpha, points + 1), n - 1.0);
    let mut worst = 0.0f64;
    for (px, &q) in reference.iter().enumerate() {
        let (mean, var) = stats(&|t| t[px]);
        let z = (mean - q) / var.sqrt();
        worst = worst.max(z.abs());
        assert!(
            z.abs() < limit,
            "{name}: point {px}: {mean:.7e} vs quadrature {q:.7e} (|z| {:.2} > {limit:.2})",
            z.abs()
        );
    }
    let (mean, var) = stats(&|t| t.iter().sum());
    let q: f64 = reference.iter().sum();
    let z = (mean - q) / var.sqrt();
    println!(
        "{name}: total {mean:.7} +- {:.7} vs quadrature {q:.7} (ratio {:.6}, z {z:+.2}); worst point |z| {worst:.2} \
         (limit {limit:.2})",
        var.sqrt(),
        mean / q
    );
    assert!(z.abs() < limit, "{name}: total {mean:.7e} vs quadrature {q:.7e} (|z| {:.2} > {limit:.2})", z.abs());
}
