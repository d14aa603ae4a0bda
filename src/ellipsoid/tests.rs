//! Checks of the oracle against itself, against finite differences and against brute force.

use std::f64::consts::TAU;

use super::*;
use crate::rng::Xorshift64Star;

/// Unit vectors for test inputs from [`Xorshift64Star`].
trait UnitDraw {
    /// A uniform unit vector (rejection from the cube).
    fn unit(&mut self) -> DVec3;
}

impl UnitDraw for Xorshift64Star {
    fn unit(&mut self) -> DVec3 {
        loop {
            let v = self.next_dvec3();
            if v.length_squared() > 0.01 && v.length_squared() <= 1.0 {
                return v.normalize();
            }
        }
    }
}

/// A random spheroid with foci in [-1, 1]^3 and length d (1 + [0.01, 2)), and a random plane
/// through a point near its centre (so most planes cut it).
fn random_case(rng: &mut Xorshift64Star) -> (Spheroid, DVec3, DVec3) {
    let (s, c) = (rng.next_dvec3(), rng.next_dvec3());
    let d = s.distance(c);
    let spheroid = Spheroid { focus_s: s, focus_c: c, length: d * (1.01 + 2.0 * rng.next_f64()) };
    let n = rng.unit();
    let point = spheroid.centre() + rng.next_dvec3() * 0.5 * spheroid.length * 0.5;
    (spheroid, point, n)
}

#[test]
fn section_points_lie_on_the_spheroid_and_the_plane() {
    let mut rng = Xorshift64Star(1);
    let mut checked = 0;
    for _ in 0..2000 {
        let (sp, point, n) = random_case(&mut rng);
        let Some(sec) = sp.section(point, n) else { continue };
        for k in 0..16 {
            let x = sec.point(k as f64 * TAU / 16.0);
            assert!(
                (sp.path_length(x) - sp.length).abs() < 1e-12 * sp.length,
                "L = {} vs {}",
                sp.path_length(x),
                sp.length
            );
            assert!(n.dot(x - point).abs() < 1e-12, "off the plane");
        }
        assert!(sec.m1 >= sec.m2 * (1.0 - 1e-12), "m1 {} < m2 {}", sec.m1, sec.m2);
        checked += 1;
    }
    assert!(checked > 1000);
}

#[test]
fn closed_form_jacobian_matches_coarea_form_and_finite_differences() {
    let mut rng = Xorshift64Star(2);
    let mut checked = 0;
    for _ in 0..2000 {
        let (sp, point, n) = random_case(&mut rng);
        let Some(sec) = sp.section(point, n) else { continue };
        if sec.shape.g < 1e-3 * sec.shape.k {
            continue; // near tangency the finite differences lose accuracy; tested separately
        }
        for k in 0..8 {
            let theta = (k as f64 + 0.37) * TAU / 8.0;
            let j = sec.jacobian(theta);
            let coarea = coarea_jacobian(&sp, &sec, n, theta);
            assert!((j - coarea).abs() < 1e-9 * coarea, "closed form {j} vs coarea {coarea}");
            // dA = |dx/dtau x dx/dtheta| dtau dtheta, by central differences.
            let dt = 1e-6 * sp.length;
            let at = |length: f64, theta: f64| Spheroid { length, ..sp }.section(point, n).unwrap().point(theta);
            let dx_dtau = (at(sp.length + dt, theta) - at(sp.length - dt, theta)) / (2.0 * dt);
            let dth = 1e-6;
            let dx_dtheta = (sec.point(theta + dth) - sec.point(theta - dth)) / (2.0 * dth);
            let fd = dx_dtau.cross(dx_dtheta).length();
            assert!((j - fd).abs() < 1e-5 * fd, "closed form {j} vs finite differences {fd}");
        }
        checked += 1;
    }
    assert!(checked > 500, "{checked}");
}

#[test]
fn jacobian_limits() {
    // Coincident foci (a sphere): J = tau / 4 at every theta and plane.
    let sp = Spheroid { focus_s: DVec3::new(0.1, 0.2, 0.3), focus_c: DVec3::new(0.1, 0.2, 0.3), length: 2.0 };
    let sec = sp.section(DVec3::new(0.1, 0.2, 0.7), DVec3::new(0.0, 0.6, 0.8)).unwrap();
    for k in 0..8 {
        let j = sec.jacobian(k as f64);
        assert!((j - 0.5).abs() < 1e-12, "J = {j}");
    }
    // Tangency: J -> a^2 b^2 / (2 K^1.5) as g -> 0.
    let sp = Spheroid { focus_s: DVec3::new(-0.3, 0.0, 0.0), focus_c: DVec3::new(0.4, 0.1, 0.0), length: 1.5 };
    let n = DVec3::new(0.3, 0.4, 0.5).normalize();
    let probe = sp.section(sp.centre(), n).unwrap().shape;
    let h = probe.k.sqrt() * (1.0 - 1e-10);
    let sec = sp.section(sp.centre() + h * n, n).unwrap();
    let s = sec.shape;
    let limit = s.a * s.a * s.b2 / (2.0 * s.k.powf(1.5));
    for k in 0..8 {
        let j = sec.jacobian(k as f64);
        assert!((j - limit).abs() < 1e-4 * limit, "J = {j} vs tangency limit {limit}");
    }
}

#[test]
fn clipped_arcs_match_a_dense_scan_of_the_ellipse() {
    let mut rng = Xorshift64Star(3);
    let mut checked = 0;
    let mut partial = 0;
    for _ in 0..600 {
        let (sp, _, _) = random_case(&mut rng);
        // A triangle around a point near the spheroid's surface, of random size and shape.
        let x0 = sp.centre() + rng.unit() * 0.5 * sp.length * 0.8;
        let scale = 0.05 + rng.next_f64() * sp.length;
        let tri = Triangle {
            vertices: [x0 + scale * rng.next_dvec3(), x0 + scale * rng.next_dvec3(), x0 + scale * rng.next_dvec3()],
        };
        let area = (tri.vertices[1] - tri.vertices[0]).cross(tri.vertices[2] - tri.vertices[0]).length();
        if area < 1e-4 {
            continue;
        }
        let n = tri.normal();
        let Some(sec) = sp.section(tri.vertices[0], n) else { continue };
        let arcs = clip_arcs(&sec, &tri);
        // Dense scan: the fraction of theta inside the triangle.
        let steps = 20_000;
        let inside = (0..steps).filter(|&k| tri.contains(sec.point((k as f64 + 0.5) * TAU / steps as f64))).count();
        let scanned = inside as f64 * TAU / steps as f64;
        // The scan errs by at most one step per arc end (<= 6 ends).
        assert!(
            (arcs.total - scanned).abs() <= 6.0 * TAU / steps as f64 + 1e-12,
            "Theta {} vs scan {scanned}",
            arcs.total
        );
        for &(a, b) in &arcs.arcs {
            assert!(0.0 <= a && a < b && b <= TAU + 1e-12);
            assert!(tri.contains(sec.point(0.5 * (a + b))), "arc midpoint outside the triangle");
        }
        // Samples uniform over the arcs lie inside (up to rounding at the ends).
        for k in 0..32 {
            let x = sec.point(arcs.sample((k as f64 + 0.5) / 32.0));
            if arcs.total > 0.0 {
                let b = tri.vertices;
                let slack = 1e-9 * scale;
                let inside_with_slack =
                    (0..3).all(|i| (b[(i + 1) % 3] - b[i]).cross(x - b[i]).dot(n) >= -slack * scale);
                assert!(inside_with_slack, "sample outside the triangle");
            }
        }
        partial += (arcs.total > 0.0 && arcs.total < TAU) as usize;
        checked += 1;
    }
    assert!(checked > 300 && partial > 100, "{checked} cases, {partial} with partial arcs");
}

#[test]
fn sections_of_a_plane_through_the_centre_have_the_expected_axes() {
    // Plane containing the axis: the section is the spheroid's meridian ellipse (a, b).
    let sp = Spheroid { focus_s: DVec3::new(-0.5, 0.0, 0.0), focus_c: DVec3::new(0.5, 0.0, 0.0), length: 1.6 };
    let sec = sp.section(DVec3::ZERO, DVec3::Z).unwrap();
    assert!((sec.m1 - 0.8).abs() < 1e-12 && (sec.m2 - sp.b2().sqrt()).abs() < 1e-12);
    assert!(sec.centre.length() < 1e-12);
    // Plane perpendicular to the axis through the centre: a circle of radius b.
    let sec = sp.section(DVec3::ZERO, DVec3::X).unwrap();
    assert!((sec.m1 - sp.b2().sqrt()).abs() < 1e-12 && (sec.m2 - sp.b2().sqrt()).abs() < 1e-12);
    // Bounds contain every section point.
    let (lo, hi) = sp.bounds();
    for k in 0..64 {
        let x =
            sp.section(DVec3::new(0.1, 0.2, 0.0), DVec3::new(0.2, 0.5, 0.8).normalize()).unwrap().point(k as f64 * 0.1);
        assert!(x.cmpge(lo - 1e-12).all() && x.cmple(hi + 1e-12).all());
    }
}
