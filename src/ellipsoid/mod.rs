//! The f64 oracle of ellipsoidal connections (docs/design.md section 5): the prolate spheroid of
//! points whose distances to two foci add up to a target length, its section by a triangle's
//! plane, the arcs of that ellipse inside the triangle, points on the arcs, and the Jacobian of
//! the change of variables (target length, eccentric angle) -> surface point, in closed form and
//! in the independent coarea form. Tests use it to check the WGSL twin; nothing here is fast.
//!
//! Units: lengths in metres; angles in radians; J in metres (m^2 of surface per metre of target
//! length per radian).

use glam::DVec3;

pub mod query;
pub mod stress;

/// A prolate spheroid: the points x with |x - focus_s| + |x - focus_c| = length.
#[derive(Clone, Copy, Debug)]
pub struct Spheroid {
    /// The light-side focus x_s (m).
    pub focus_s: DVec3,
    /// The camera-side focus x_c (m).
    pub focus_c: DVec3,
    /// The sum of distances to the foci, tau_e (m); at least the foci's distance.
    pub length: f64,
}

/// The ellipse in which a plane cuts a spheroid.
#[derive(Clone, Copy, Debug)]
pub struct Section {
    /// Centre o (m).
    pub centre: DVec3,
    /// Unit major axis u.
    pub u: DVec3,
    /// Unit minor axis v = n x u.
    pub v: DVec3,
    /// Semi-axis along u, m1 (m).
    pub m1: f64,
    /// Semi-axis along v, m2 (m).
    pub m2: f64,
    /// The quantities the Jacobian needs: a, b^2, c, h, cos psi, sin psi, K, g.
    pub shape: SectionShape,
}

/// The scalars of a plane section (docs/design.md section 5.2 names).
#[derive(Clone, Copy, Debug)]
pub struct SectionShape {
    /// Semi-major axis of the spheroid, tau_e / 2 (m).
    pub a: f64,
    /// Squared semi-minor axis of the spheroid, (a - c)(a + c) (m^2).
    pub b2: f64,
    /// Half the foci's distance (m).
    pub c: f64,
    /// Signed distance of the plane from the spheroid's centre along n (m).
    pub h: f64,
    /// Cosine of the angle between the plane's normal and the spheroid's axis.
    pub cos_psi: f64,
    /// Its sine (>= 0).
    pub sin_psi: f64,
    /// b^2 + c^2 cos^2 psi (m^2).
    pub k: f64,
    /// K - h^2 (m^2): the plane cuts the spheroid iff g > 0.
    pub g: f64,
}

impl Spheroid {
    /// Half the distance between the foci, c (m).
    pub fn c(&self) -> f64 {
        0.5 * self.focus_s.distance(self.focus_c)
    }

    /// Semi-major axis a = length / 2 (m).
    pub fn a(&self) -> f64 {
        0.5 * self.length
    }

    /// Squared semi-minor axis b^2 = (a - c)(a + c), from the difference (never a difference of
    /// large squares).
    pub fn b2(&self) -> f64 {
        let d = self.focus_s.distance(self.focus_c);
        0.25 * (self.length - d) * (self.length + d)
    }

    /// Centre (m).
    pub fn centre(&self) -> DVec3 {
        0.5 * (self.focus_s + self.focus_c)
    }

    /// Unit axis from focus_s to focus_c (+z for coincident foci).
    pub fn axis(&self) -> DVec3 {
        (self.focus_c - self.focus_s).try_normalize().unwrap_or(DVec3::Z)
    }

    /// L(x) = |x - focus_s| + |x - focus_c| (m).
    pub fn path_length(&self, x: DVec3) -> f64 {
        x.distance(self.focus_s) + x.distance(self.focus_c)
    }

    /// Axis-aligned bounds (min, max) of the spheroid: centre -/+ sqrt(b^2 + c^2 e_i^2).
    pub fn bounds(&self) -> (DVec3, DVec3) {
        let e = self.axis();
        let (b2, c) = (self.b2(), self.c());
        let half = DVec3::new(
            (b2 + c * c * e.x * e.x).sqrt(),
            (b2 + c * c * e.y * e.y).sqrt(),
            (b2 + c * c * e.z * e.z).sqrt(),
        );
        (self.centre() - half, self.centre() + half)
    }

    /// The ellipse in which the plane through `point` with unit normal `n` cuts the spheroid;
    /// None when it misses or touches (g <= 0) or the spheroid is degenerate (length <= d).
    pub fn section(&self, point: DVec3, n: DVec3) -> Option<Section> {
        let (a, c, b2) = (self.a(), self.c(), self.b2());
        if b2 <= 0.0 {
            return None;
        }
        let m = self.centre();
        let e = self.axis();
        let h = n.dot(point - m);
        let cos_psi = n.dot(e);
        let in_plane = e - cos_psi * n;
        let sin_psi = in_plane.length();
        let k = b2 + c * c * cos_psi * cos_psi;
        let g = k - h * h;
        if g <= 0.0 {
            return None;
        }
        let u = if sin_psi > 1e-12 { in_plane / sin_psi } else { n.any_orthonormal_vector() };
        let v = n.cross(u);
        let m1 = a * b2.sqrt() * g.sqrt() / k;
        let m2 = b2.sqrt() * (g / k).sqrt();
        let u0 = h * c * c * cos_psi * sin_psi / k;
        let centre = m + h * n + u0 * u;
        let shape = SectionShape { a, b2, c, h, cos_psi, sin_psi, k, g };
        Some(Section { centre, u, v, m1, m2, shape })
    }
}

impl Section {
    /// The point at eccentric angle theta: o + m1 cos(theta) u + m2 sin(theta) v (m).
    pub fn point(&self, theta: f64) -> DVec3 {
        self.centre + self.m1 * theta.cos() * self.u + self.m2 * theta.sin() * self.v
    }

    /// |dx/dtheta| (m per radian).
    pub fn speed(&self, theta: f64) -> f64 {
        (self.m1 * self.m1 * theta.sin().powi(2) + self.m2 * self.m2 * theta.cos().powi(2)).sqrt()
    }

    /// The closed-form Jacobian J (m) of (target length, theta) -> surface point:
    /// dA = J dtau dtheta (docs/design.md section 5.4).
    pub fn jacobian(&self, theta: f64) -> f64 {
        let SectionShape { a, b2, c, h, cos_psi, sin_psi, k, g } = self.shape;
        let u0_prime = -a * h * c * c * cos_psi * sin_psi / (k * k);
        let m1_sq_prime = a / (k * k) * (b2 * g + a * a * g + a * a * b2 - 2.0 * a * a * b2 * g / k);
        let m2_sq_prime = a * (g * k + b2 * h * h) / (k * k);
        let (ct, st) = (theta.cos(), theta.sin());
        u0_prime * self.m2 * ct
            + m1_sq_prime * (k.sqrt() / (2.0 * a)) * ct * ct
            + m2_sq_prime * (a / (2.0 * k.sqrt())) * st * st
    }
}

/// J = |dx/dtheta| / |grad_parallel L(x)|, the coarea form (an independent check of
/// [`Section::jacobian`]): the in-plane gradient of the path length at x (n the plane's normal).
pub fn coarea_jacobian(spheroid: &Spheroid, section: &Section, n: DVec3, theta: f64) -> f64 {
    let x = section.point(theta);
    let grad = (x - spheroid.focus_s).normalize() + (x - spheroid.focus_c).normalize();
    let in_plane = grad - grad.dot(n) * n;
    section.speed(theta) / in_plane.length()
}

/// A triangle with vertices counter-clockwise about `normal`.
#[derive(Clone, Copy, Debug)]
pub struct Triangle {
    /// Vertices (m).
    pub vertices: [DVec3; 3],
}

impl Triangle {
    /// Unit normal (counter-clockwise winding).
    pub fn normal(&self) -> DVec3 {
        let [p0, p1, p2] = self.vertices;
        (p1 - p0).cross(p2 - p0).normalize()
    }

    /// True when x (on the plane) lies inside or on the edges.
    pub fn contains(&self, x: DVec3) -> bool {
        let n = self.normal();
        (0..3).all(|i| {
            let (p, q) = (self.vertices[i], self.vertices[(i + 1) % 3]);
            (q - p).cross(x - p).dot(n) >= 0.0
        })
    }
}

/// Arcs [start, end) of eccentric angle (radians, start in [0, 2 pi), end - start > 0, possibly
/// past 2 pi only through splitting: every arc lies within [0, 2 pi]) of the section's ellipse
/// inside the triangle, and their total Theta.
#[derive(Clone, Debug, Default)]
pub struct Arcs {
    /// The arcs, in increasing order.
    pub arcs: Vec<(f64, f64)>,
    /// Their total length in theta (radians).
    pub total: f64,
}

impl Arcs {
    /// The angle at fraction `u` in [0, 1) of the total: theta uniform over the arcs.
    pub fn sample(&self, u: f64) -> f64 {
        let mut left = u * self.total;
        for &(a, b) in &self.arcs {
            if left < b - a {
                return a + left;
            }
            left -= b - a;
        }
        self.arcs.last().map_or(0.0, |a| a.1)
    }
}

/// The arcs of `section` inside `triangle` (docs/design.md section 5.3, arc clipping): each edge keeps
/// alpha cos + beta sin >= gamma, an interval about phi = atan2(beta, alpha); break points at 0,
/// 2 pi and the interval ends; the sub-intervals whose midpoints pass all edges are kept.
pub fn clip_arcs(section: &Section, triangle: &Triangle) -> Arcs {
    use std::f64::consts::TAU;
    let n = triangle.normal();
    let mut breaks = vec![0.0, TAU];
    let mut edges = Vec::with_capacity(3);
    for i in 0..3 {
        let p = triangle.vertices[i];
        let e = triangle.vertices[(i + 1) % 3] - p;
        let alpha = section.m1 * e.cross(section.u).dot(n);
        let beta = section.m2 * e.cross(section.v).dot(n);
        let gamma = -e.cross(section.centre - p).dot(n);
        edges.push((alpha, beta, gamma));
        let r = alpha.hypot(beta);
        if r > 0.0 {
            let ratio = gamma / r;
            if ratio > -1.0 && ratio < 1.0 {
                let phi = beta.atan2(alpha);
                let w = ratio.acos();
                breaks.push((phi - w).rem_euclid(TAU));
                breaks.push((phi + w).rem_euclid(TAU));
            }
        }
    }
    breaks.sort_by(f64::total_cmp);
    let mut arcs: Vec<(f64, f64)> = Vec::new();
    for pair in breaks.windows(2) {
        let (a, b) = (pair[0], pair[1]);
        if b <= a {
            continue;
        }
        let mid = 0.5 * (a + b);
        let (cm, sm) = (mid.cos(), mid.sin());
        if edges.iter().all(|&(alpha, beta, gamma)| alpha * cm + beta * sm >= gamma) {
            match arcs.last_mut() {
                Some(last) if last.1 == a => last.1 = b,
                _ => arcs.push((a, b)),
            }
        }
    }
    let total = arcs.iter().map(|(a, b)| b - a).sum();
    Arcs { arcs, total }
}

#[cfg(test)]
mod tests;
