//! Participating media: homogeneous media and heterogeneous ones on a grid of voxels (Mitsuba's
//! `heterogeneous` medium over a `gridvolume`), bounded by `null` surfaces (Mitsuba's `null` BSDF
//! with an `interior` medium) or around the camera, and the CPU twin of `shaders/lib/medium.wesl`
//! (the Henyey-Greenstein phase function, its sampling, transmittance, grid lookups).
//!
//! Conventions: a phase function is written in terms of mu, the cosine between the direction a
//! ray travelled in and the direction it leaves in, so mu = 1 is no deflection; a positive mean
//! cosine g scatters forward (Mitsuba's and pbrt's `hg` alike).

use anyhow::{Context as _, Result};
use glam::{Mat4, Vec3};

use crate::gpu::layout::{Medium, NONE};

/// A medium as loaded.
#[derive(Clone, Debug, PartialEq)]
pub struct MediumDesc {
    /// Where it was declared (file and element), for messages.
    pub name: String,
    /// Extinction coefficient sigma_t (m^-1), the same in every channel; with a grid, its
    /// largest (the majorant), which the grid's values scale.
    pub sigma_t: f32,
    /// Single-scattering albedo sigma_s / sigma_t (linear RGB, 0..1); with an albedo grid
    /// (`DensityGrid::albedo`), the factor on its values (1).
    pub albedo: Vec3,
    /// Mean cosine of the Henyey-Greenstein phase function (-1 < g < 1; 0: isotropic).
    pub g: f32,
    /// The extinction's shares of `sigma_t` on a grid (a heterogeneous medium), None where it is
    /// the same everywhere.
    pub grid: Option<DensityGrid>,
}

impl MediumDesc {
    /// The medium in the kernels' layout, its grid's values starting at `grid_offset` in
    /// `medium_densities`, followed by its albedo grid's ([`DensityGrid::densities`]).
    pub fn to_gpu(&self, grid_offset: u32) -> Medium {
        let mut m = Medium {
            albedo: self.albedo,
            sigma_t: self.sigma_t,
            g: self.g,
            grid: NONE,
            albedo_grid: NONE,
            ..Default::default()
        };
        if let Some(grid) = &self.grid {
            m.grid = grid_offset;
            m.albedo_grid = match grid.albedo {
                Some(_) => grid_offset + grid.values.len() as u32,
                None => NONE,
            };
            m.grid_nearest = grid.nearest as u32;
            m.grid_resolution = grid.resolution;
            let rows = grid.world_to_grid.transpose();
            m.world_to_grid = [rows.x_axis.to_array(), rows.y_axis.to_array(), rows.z_axis.to_array()];
        }
        m
    }
}

/// The extinction of a heterogeneous medium on a grid of voxels spanning a box: the unit cube
/// that `world_to_grid` maps world space onto. Values are shares of the medium's majorant, in
/// [0, 1]; outside the box the medium holds nothing.
#[derive(Clone, Debug, PartialEq)]
pub struct DensityGrid {
    /// Voxels along x, y and z.
    pub resolution: [u32; 3],
    /// One value per voxel, x fastest, then y, then z.
    pub values: Vec<f32>,
    /// Affine map from world space (m) to the grid's unit cube.
    pub world_to_grid: Mat4,
    /// Lookups take the nearest voxel's value (else trilinear interpolation between the voxels'
    /// centres, clamped at the box's faces, as Mitsuba's `gridvolume` does by default).
    pub nearest: bool,
    /// The single-scattering albedo (linear RGB, 0..1) on the same voxels, three values a voxel,
    /// looked up alike; None where the medium has one albedo.
    pub albedo: Option<Vec<f32>>,
}

impl DensityGrid {
    /// The share of the majorant at world point `p` (twin of `grid_share` in medium.wesl).
    pub fn share(&self, p: Vec3) -> f32 {
        self.lookup(|i| self.values[i], p)
    }

    /// The albedo grid's value at world point `p`, None without one (twin of `medium_albedo`'s
    /// lookup in medium.wesl).
    pub fn albedo_at(&self, p: Vec3) -> Option<Vec3> {
        let a = self.albedo.as_ref()?;
        Some(Vec3::from_array(std::array::from_fn(|c| self.lookup(|i| a[3 * i + c], p))))
    }

    /// Sets the albedo from a grid of `channels` values a voxel (1: grey, 3: RGB) on `resolution`
    /// voxels, which must be this grid's; every value must lie within [0, 1].
    pub fn set_albedo(&mut self, resolution: [u32; 3], channels: u32, values: Vec<f32>) -> Result<()> {
        let (r, own) = (resolution, self.resolution);
        anyhow::ensure!(
            r == own,
            "the albedo grid ({} x {} x {}) must share the extinction grid's voxels ({} x {} x {})",
            r[0],
            r[1],
            r[2],
            own[0],
            own[1],
            own[2]
        );
        if let Some(bad) = values.iter().position(|&a| a > 1.0) {
            anyhow::bail!("albedo {} (value {bad}) is not within [0, 1]", values[bad]);
        }
        self.albedo = Some(if channels == 3 { values } else { values.iter().flat_map(|&a| [a; 3]).collect() });
        Ok(())
    }

    /// What the kernels read in `medium_densities`: the extinction's shares, then the albedos.
    pub fn densities(&self) -> impl Iterator<Item = f32> + '_ {
        self.values.iter().chain(self.albedo.iter().flatten()).copied()
    }

    /// The value of voxel `i` (x fastest, then y, then z; `value`) at world point `p`: the
    /// nearest voxel's, or interpolated trilinearly between the voxels' centres, clamped at the
    /// box's faces; zero outside the box (twin of `grid_lookup` in medium.wesl).
    fn lookup(&self, value: impl Fn(usize) -> f32, p: Vec3) -> f32 {
        let u = self.world_to_grid.transform_point3(p);
        if u.min_element() < 0.0 || u.max_element() > 1.0 {
            return 0.0;
        }
        let res = self.resolution;
        let at = |x: i64, y: i64, z: i64| -> f32 {
            let c = |i: i64, n: u32| i.clamp(0, n as i64 - 1) as usize;
            let (x, y, z) = (c(x, res[0]), c(y, res[1]), c(z, res[2]));
            value((z * res[1] as usize + y) * res[0] as usize + x)
        };
        let scaled = u * Vec3::new(res[0] as f32, res[1] as f32, res[2] as f32);
        if self.nearest {
            let i = scaled.floor();
            return at(i.x as i64, i.y as i64, i.z as i64);
        }
        let p = scaled - 0.5;
        let i = p.floor();
        let f = p - i;
        let (x, y, z) = (i.x as i64, i.y as i64, i.z as i64);
        let lerp = |a: f32, b: f32, t: f32| a + (b - a) * t;
        let c00 = lerp(at(x, y, z), at(x + 1, y, z), f.x);
        let c10 = lerp(at(x, y + 1, z), at(x + 1, y + 1, z), f.x);
        let c01 = lerp(at(x, y, z + 1), at(x + 1, y, z + 1), f.x);
        let c11 = lerp(at(x, y + 1, z + 1), at(x + 1, y + 1, z + 1), f.x);
        lerp(lerp(c00, c10, f.y), lerp(c01, c11, f.y), f.z)
    }
}

/// A grid read from a file in Mitsuba's volume format (`.vol`: "VOL", version 3, encoding 1
/// (f32), the resolution, the channel count, a bounding box, then the values little-endian,
/// channels innermost, then x, y, z): (resolution, channels (1 or 3), values).
pub fn read_vol(path: &std::path::Path) -> Result<([u32; 3], u32, Vec<f32>)> {
    let bytes = std::fs::read(path).with_context(|| format!("cannot read the volume {}", path.display()))?;
    let name = path.display();
    anyhow::ensure!(
        bytes.len() >= 48 && &bytes[..3] == b"VOL",
        "{name}: not a volume file (it does not start with VOL)"
    );
    anyhow::ensure!(bytes[3] == 3, "{name}: volume format version {} (3 is read)", bytes[3]);
    let word = |i: usize| i32::from_le_bytes(bytes[4 + 4 * i..8 + 4 * i].try_into().unwrap());
    anyhow::ensure!(word(0) == 1, "{name}: encoding {} (1, 32-bit floats, is read)", word(0));
    let (x, y, z, channels) = (word(1), word(2), word(3), word(4));
    anyhow::ensure!(x > 0 && y > 0 && z > 0, "{name}: resolution {x} x {y} x {z} is not positive");
    anyhow::ensure!(channels == 1 || channels == 3, "{name}: {channels} channels (grids of 1 or 3 are read)");
    let count = x as usize * y as usize * z as usize * channels as usize;
    let expected = 48 + 4 * count;
    anyhow::ensure!(
        bytes.len() == expected,
        "{name}: {} bytes where a {x} x {y} x {z} grid of {channels} channel(s) takes {expected}",
        bytes.len()
    );
    let values: Vec<f32> = bytes[48..].chunks_exact(4).map(|b| f32::from_le_bytes(b.try_into().unwrap())).collect();
    if let Some(bad) = values.iter().position(|v| !(v.is_finite() && *v >= 0.0)) {
        anyhow::bail!("{name}: value {bad} ({}) is not a finite non-negative number", values[bad]);
    }
    Ok(([x as u32, y as u32, z as u32], channels as u32, values))
}

/// Writes a grid in Mitsuba's volume format (see [`read_vol`]), with the unit cube as its
/// bounding box: one channel, or as many as `values` holds per voxel.
pub fn write_vol(path: &std::path::Path, resolution: [u32; 3], values: &[f32]) -> Result<()> {
    let voxels = resolution.iter().map(|&r| r as usize).product::<usize>().max(1);
    let channels = (values.len() / voxels).max(1) as i32;
    let mut bytes = b"VOL\x03".to_vec();
    for w in [1, resolution[0] as i32, resolution[1] as i32, resolution[2] as i32, channels] {
        bytes.extend_from_slice(&w.to_le_bytes());
    }
    for b in [0.0f32, 0.0, 0.0, 1.0, 1.0, 1.0] {
        bytes.extend_from_slice(&b.to_le_bytes());
    }
    for v in values {
        bytes.extend_from_slice(&v.to_le_bytes());
    }
    std::fs::write(path, bytes).with_context(|| format!("cannot write {}", path.display()))
}

impl MediumDesc {
    /// A fog given as `SIGMA_T[,ALBEDO[,G]]`: extinction sigma_t (m^-1, positive), albedo (0..1,
    /// default 0.9) and the phase function's mean cosine g (-1 < g < 1, default 0.8, forward as
    /// droplets scatter), as `--fog` takes it.
    pub fn parse_fog(spec: &str) -> anyhow::Result<Self> {
        let numbers: Vec<f32> = spec
            .split(',')
            .map(|x| x.trim().parse::<f32>().ok().filter(|x| x.is_finite()))
            .collect::<Option<_>>()
            .ok_or_else(|| anyhow::anyhow!("`{spec}` is not SIGMA_T[,ALBEDO[,G]] (numbers)"))?;
        let (sigma_t, albedo, g) = match numbers[..] {
            [s] => (s, 0.9, 0.8),
            [s, a] => (s, a, 0.8),
            [s, a, g] => (s, a, g),
            _ => anyhow::bail!("`{spec}` is not SIGMA_T[,ALBEDO[,G]]: at most three numbers"),
        };
        anyhow::ensure!(sigma_t > 0.0, "fog `{spec}`: the extinction {sigma_t} m^-1 is not positive");
        anyhow::ensure!((0.0..=1.0).contains(&albedo), "fog `{spec}`: the albedo {albedo} is not within [0, 1]");
        anyhow::ensure!(g > -1.0 && g < 1.0, "fog `{spec}`: g {g} is not within (-1, 1)");
        Ok(MediumDesc { name: format!("fog {spec}"), sigma_t, albedo: Vec3::splat(albedo), g, grid: None })
    }
}

/// The media on the two sides of a surface, indices into `Scene::media` (None: vacuum).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct MediumInterface {
    /// Behind the triangles' front faces (inside a closed, outward-wound mesh).
    pub interior: Option<u32>,
    /// In front of them.
    pub exterior: Option<u32>,
}

/// The Henyey-Greenstein phase function of mean cosine `g` at cosine `mu` between the directions
/// of travel before and after scattering (sr^-1; twin of `hg_phase`).
pub fn hg_phase(mu: f32, g: f32) -> f32 {
    let denominator = 1.0 + g * g - 2.0 * g * mu;
    (1.0 - g * g) / (4.0 * std::f32::consts::PI * denominator * denominator.sqrt())
}

/// The cosine mu drawn from the Henyey-Greenstein phase function of mean cosine `g` by inverting
/// its distribution at `u` in [0, 1) (twin of `sample_hg_cosine`).
pub fn sample_hg_cosine(g: f32, u: f32) -> f32 {
    if g.abs() < 1e-3 {
        return 2.0 * u - 1.0;
    }
    let s = (1.0 - g * g) / (1.0 - g + 2.0 * g * u);
    ((1.0 + g * g - s * s) / (2.0 * g)).clamp(-1.0, 1.0)
}

/// A unit direction drawn from the Henyey-Greenstein phase function about unit direction of
/// travel `d`, with `u` in [0, 1)^2, and its density (sr^-1; twin of `sample_hg`).
pub fn sample_hg(d: Vec3, g: f32, u: [f32; 2]) -> (Vec3, f32) {
    let mu = sample_hg_cosine(g, u[0]);
    let sin = (1.0 - mu * mu).max(0.0).sqrt();
    let phi = 2.0 * std::f32::consts::PI * u[1];
    let (x, y) = d.any_orthonormal_pair();
    let w = (x * phi.cos() + y * phi.sin()) * sin + d * mu;
    (w.normalize(), hg_phase(mu, g))
}

/// The share of light that crosses a distance `t` (m) of a medium of extinction `sigma_t`
/// (m^-1) unscattered: exp(-sigma_t t).
pub fn transmittance(sigma_t: f32, t: f32) -> f32 {
    (-sigma_t * t).exp()
}

/// The f64 oracle of a medium connection's placement (the kernels' `spheroid_crossing`, docs/design.md
/// section 4.1): where the ray from `o` along unit `w` meets the spheroid of foci `o` and `y` and
/// length `r` (m), and how fast the length grows there: (t (m), dtau/dt), from the f32 inputs
/// widened exactly and `w` normalised, by the textbook formulas in f64: t = (r^2 - |p|^2) /
/// (2 (r + p . w)) with p = o - y, and 1 - w . (y - z) / |y - z|; None where r <= |o - y|.
pub fn medium_connection_oracle(o: Vec3, w: Vec3, y: Vec3, r: f32) -> Option<(f64, f64)> {
    let (o, w, y, r) = (o.as_dvec3(), w.as_dvec3().normalize(), y.as_dvec3(), r as f64);
    let p = o - y;
    if r <= p.length() {
        return None;
    }
    let t = (r * r - p.length_squared()) / (2.0 * (r + p.dot(w)));
    let z = o + t * w;
    Some((t, 1.0 - w.dot((y - z).normalize())))
}

/// The medium at point `p` (m) as light leaving it travels in: an index of `scene.media`, or
/// None for vacuum. Space is divided by the surfaces that declare media
/// ([`MediumInterface`]: null boundaries, glass holding a medium); others leave a ray in the
/// medium it came through. So the nearest such surface seen from `p` ([`nearest_boundary`])
/// decides: its exterior medium where `p` lies in front of it, its interior one behind it. Where
/// none is seen, `p` lies in the space no boundary encloses, which holds the camera's medium (a
/// fog). Light subpaths start in their light's medium.
pub fn medium_at(scene: &super::Scene, p: Vec3) -> Option<u32> {
    match nearest_boundary(scene, p, |m| m.media != MediumInterface::default()) {
        Some((true, m)) => m.media.exterior,
        Some((false, m)) => m.media.interior,
        None => scene.camera_medium,
    }
}

/// The index of refraction of the space at point `p` (m): the relative index of the nearest
/// glass (a smooth or rough dielectric, not a thin pane) seen from `p` where `p` lies behind its
/// front faces (inside it, in air), 1 elsewhere. Optical lengths from a light inside glass count
/// that index.
pub fn index_of_refraction_at(scene: &super::Scene, p: Vec3) -> f32 {
    let glass = |m: &super::MaterialDesc| m.dielectric.is_some_and(|d| !d.thin);
    match nearest_boundary(scene, p, glass) {
        Some((false, m)) => m.dielectric.map_or(1.0, |d| d.eta),
        _ => 1.0,
    }
}

/// The nearest triangle whose material passes `filter`, seen from `p` (m) along 14 directions
/// (the axes and the diagonals), and whether `p` lies in front of it.
fn nearest_boundary(
    scene: &super::Scene,
    p: Vec3,
    filter: impl Fn(&super::MaterialDesc) -> bool,
) -> Option<(bool, &super::MaterialDesc)> {
    let mut directions = Vec::with_capacity(14);
    for axis in [Vec3::X, Vec3::Y, Vec3::Z] {
        directions.extend([axis, -axis]);
    }
    for x in [-1.0f32, 1.0] {
        for y in [-1.0f32, 1.0] {
            for z in [-1.0f32, 1.0] {
                directions.push(Vec3::new(x, y, z).normalize());
            }
        }
    }
    // (distance, in front of it, its material).
    let mut nearest: Option<(f32, bool, &super::MaterialDesc)> = None;
    for t in &scene.triangles {
        let m = &scene.materials[t.material as usize];
        if !filter(m) {
            continue;
        }
        let [a, b, c] = t.positions;
        let n = (b - a).cross(c - a);
        for &d in &directions {
            if let Some(distance) = ray_triangle(p, d, a, b, c)
                && nearest.is_none_or(|(best, _, _)| distance < best)
            {
                nearest = Some((distance, d.dot(n) < 0.0, m));
            }
        }
    }
    nearest.map(|(_, front, m)| (front, m))
}

/// Distance (m) along unit direction `d` from `o` to triangle (a, b, c), if the ray meets it
/// (Moller-Trumbore, in f64).
fn ray_triangle(o: Vec3, d: Vec3, a: Vec3, b: Vec3, c: Vec3) -> Option<f32> {
    let (o, d, a, b, c) = (o.as_dvec3(), d.as_dvec3(), a.as_dvec3(), b.as_dvec3(), c.as_dvec3());
    let (e1, e2) = (b - a, c - a);
    let q = d.cross(e2);
    let det = e1.dot(q);
    if det.abs() < 1e-300 {
        return None;
    }
    let s = (o - a) / det;
    let u = s.dot(q);
    let r = s.cross(e1);
    let v = d.dot(r);
    let t = e2.dot(r);
    (u >= 0.0 && v >= 0.0 && u + v <= 1.0 && t > 0.0).then_some(t as f32)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The oracle's vertex lies on the spheroid (t + |y - z| = r), and its rate is the
    /// derivative of the length along the ray (central differences).
    #[test]
    fn medium_connections_place_their_vertex_on_the_spheroid() {
        let mut rng = crate::rng::Rng::new(17, 0, 0);
        let mut v = || Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 4.0 - 2.0;
        for _ in 0..1000 {
            let (o, y, w) = (v(), v(), v().normalize());
            let r = (o - y).length() + 0.05 + v().x.abs();
            let (t, rate) = medium_connection_oracle(o, w, y, r).unwrap();
            // Along the unit direction the oracle takes (w / |w| in f64).
            let length = |t: f64| t + (y.as_dvec3() - (o.as_dvec3() + t * w.as_dvec3().normalize())).length();
            assert!(t > 0.0 && (length(t) - r as f64).abs() < 1e-12 * r as f64, "length {} against {r}", length(t));
            let h = 1e-6;
            let derivative = (length(t + h) - length(t - h)) / (2.0 * h);
            assert!((derivative - rate).abs() < 1e-6, "dtau/dt {derivative} against {rate}");
        }
        assert_eq!(medium_connection_oracle(Vec3::ZERO, Vec3::X, Vec3::Y, 0.9), None);
    }

    /// The phase function integrates to one over the sphere and has mean cosine g.
    #[test]
    fn hg_phase_is_normalised_with_mean_cosine_g() {
        for g in [-0.7f32, -0.2, 0.0, 0.3, 0.5, 0.9] {
            let n = 200_000;
            let (mut total, mut mean) = (0.0f64, 0.0f64);
            for i in 0..n {
                let mu = -1.0 + 2.0 * (i as f64 + 0.5) / n as f64;
                let p = hg_phase(mu as f32, g) as f64 * 2.0 * std::f64::consts::PI * 2.0 / n as f64;
                total += p;
                mean += p * mu;
            }
            assert!((total - 1.0).abs() < 1e-3, "g {g}: integral {total}");
            assert!((mean - g as f64).abs() < 2e-3, "g {g}: mean cosine {mean}");
        }
    }

    /// A grid written and read back keeps its values; lookups interpolate between the voxels'
    /// centres, clamp at the box's faces and give zero outside; nearest lookups take the voxel.
    #[test]
    fn a_density_grid_reads_back_and_interpolates_between_voxel_centres() {
        let dir = std::env::temp_dir().join(format!("gatetrace_vol_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("ramp.vol");
        let values = [0.0, 1.0, 0.5, 0.25, 0.8, 0.6, 0.2, 0.4];
        write_vol(&path, [2, 2, 2], &values).unwrap();
        let (resolution, channels, read) = read_vol(&path).unwrap();
        assert_eq!((resolution, channels, read.as_slice()), ([2, 2, 2], 1, &values[..]));
        // The box [-1, 1]^3.
        let world_to_grid = Mat4::from_scale(Vec3::splat(0.5)) * Mat4::from_translation(Vec3::ONE);
        let mut grid = DensityGrid { resolution, values: read, world_to_grid, nearest: false, albedo: None };
        // Voxel centres (+-0.5), the midpoint between them, clamped faces, outside.
        assert_eq!(grid.share(Vec3::new(-0.5, -0.5, -0.5)), 0.0);
        assert_eq!(grid.share(Vec3::new(0.5, -0.5, -0.5)), 1.0);
        assert!((grid.share(Vec3::new(0.0, -0.5, -0.5)) - 0.5).abs() < 1e-6);
        assert_eq!(grid.share(Vec3::new(0.9, -0.9, -0.9)), 1.0);
        let mean: f32 = values.iter().sum::<f32>() / 8.0;
        assert!((grid.share(Vec3::ZERO) - mean).abs() < 1e-6);
        assert_eq!(grid.share(Vec3::new(1.01, 0.0, 0.0)), 0.0);
        grid.nearest = true;
        assert_eq!(grid.share(Vec3::new(0.1, 0.9, 0.9)), 0.4);
        assert_eq!(grid.share(Vec3::new(-0.1, -0.9, -0.9)), 0.0);
        // An albedo grid on the same voxels is looked up alike and follows the extinction's values
        // in what the kernels read.
        assert_eq!(grid.albedo_at(Vec3::ZERO), None);
        grid.albedo = Some(values.iter().flat_map(|v| [1.0 - v, 0.5, *v]).collect());
        assert_eq!(grid.albedo_at(Vec3::new(0.1, 0.9, 0.9)), Some(Vec3::new(0.6, 0.5, 0.4)));
        assert_eq!(grid.albedo_at(Vec3::new(1.01, 0.0, 0.0)), Some(Vec3::ZERO));
        grid.nearest = false;
        let a = grid.albedo_at(Vec3::ZERO).unwrap();
        assert!((a - Vec3::new(1.0 - mean, 0.5, mean)).abs().max_element() < 1e-6, "{a}");
        let densities: Vec<f32> = grid.densities().collect();
        assert_eq!((densities.len(), densities[8], densities[9], densities[10]), (32, 1.0, 0.5, 0.0));
        // Three channels written and read back.
        write_vol(&path, [2, 2, 2], grid.albedo.as_ref().unwrap()).unwrap();
        let (resolution, channels, read) = read_vol(&path).unwrap();
        assert_eq!((resolution, channels, &read), ([2, 2, 2], 3, grid.albedo.as_ref().unwrap()));
        // A file of the wrong size is refused, naming it.
        std::fs::write(&path, &std::fs::read(&path).unwrap()[..60]).unwrap();
        let e = read_vol(&path).unwrap_err().to_string();
        assert!(e.contains("ramp.vol") && e.contains("bytes"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// Inverting the distribution: mu is -1 at u = 0, 1 at u = 1, and increasing.
    #[test]
    fn hg_cosine_sampling_spans_minus_one_to_one() {
        for g in [-0.8f32, 0.0, 0.4, 0.95] {
            assert!((sample_hg_cosine(g, 0.0) + 1.0).abs() < 1e-5);
            assert!((sample_hg_cosine(g, 1.0) - 1.0).abs() < 1e-5);
            let mut last = -1.0;
            for i in 1..100 {
                let mu = sample_hg_cosine(g, i as f32 / 100.0);
                assert!(mu >= last, "g {g}: not increasing at {i}");
                last = mu;
            }
        }
    }
}
