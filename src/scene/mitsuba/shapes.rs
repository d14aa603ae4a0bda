//! The shapes of the Mitsuba 3 loader as triangle meshes in the shape's own space: OBJ files
//! (through `tobj`), PLY files (through `ply-rs-bw`), Mitsuba's own `serialized` files, and
//! Mitsuba's primitives (`rectangle`,
//! `cube`, `disk`, `cylinder`, and `sphere`), the curved ones tessellated so that no point of the
//! mesh lies farther than [`TESSELLATION_ERROR`] x radius from the true surface.

use std::path::Path;

use anyhow::{Result, anyhow, bail};
use glam::{Vec2, Vec3};

/// The largest distance (relative to the radius) between a tessellated sphere, disk or cylinder
/// and the surface it stands for: Mitsuba's analytic shapes become meshes this close to them.
/// Each mesh is also scaled about its axis or centre to the true surface's area (its vertices a
/// few 10^-4 outside, its faces' middles inside), so that the light it reflects or emits is the
/// analytic shape's: an inscribed 100-gon has 6.6e-4 less area than its disk.
pub const TESSELLATION_ERROR: f32 = 5e-4;

/// A triangle mesh: positions (scene units), optional unit vertex normals, optional texture
/// coordinates, and vertex indices three per triangle, counter-clockwise about the front.
#[derive(Clone, Debug, Default)]
pub struct Mesh {
    pub positions: Vec<Vec3>,
    pub normals: Option<Vec<Vec3>>,
    pub uvs: Option<Vec<Vec2>>,
    pub indices: Vec<u32>,
}

impl Mesh {
    /// Sum of the triangles' areas (square scene units), in f64.
    pub fn area(&self) -> f64 {
        self.indices
            .chunks_exact(3)
            .map(|t| {
                let [a, b, c] = [0, 1, 2].map(|k| self.positions[t[k] as usize].as_dvec3());
                0.5 * (b - a).cross(c - a).length()
            })
            .sum()
    }

    /// Gives a mesh without vertex normals smooth ones, as Mitsuba does for a mesh file without
    /// `face_normals`: at each vertex the sum of its triangles' unit normals weighted by their
    /// angles there, normalised (a vertex whose sum vanishes keeps its triangles' own normals:
    /// those triangles get none).
    pub fn smooth_normals(&mut self) {
        if self.normals.is_some() {
            return;
        }
        let mut sums = vec![Vec3::ZERO; self.positions.len()];
        for t in self.indices.chunks_exact(3) {
            let p = [0, 1, 2].map(|k| self.positions[t[k] as usize]);
            let n = (p[1] - p[0]).cross(p[2] - p[0]).normalize_or_zero();
            for k in 0..3 {
                let (a, b) = ((p[(k + 1) % 3] - p[k]).normalize_or_zero(), (p[(k + 2) % 3] - p[k]).normalize_or_zero());
                sums[t[k] as usize] += n * a.dot(b).clamp(-1.0, 1.0).acos();
            }
        }
        self.normals = Some(sums.into_iter().map(Vec3::normalize_or_zero).collect());
    }

    /// Checks that every index names a vertex and the attribute counts match (`name`: the file).
    fn checked(self, name: &str) -> Result<Mesh> {
        let n = self.positions.len();
        if let Some(&i) = self.indices.iter().find(|&&i| i as usize >= n) {
            bail!("{name}: vertex index {i} is out of range ({n} vertices)");
        }
        if self.normals.as_ref().is_some_and(|v| v.len() != n) || self.uvs.as_ref().is_some_and(|v| v.len() != n) {
            bail!("{name}: the normal or texture-coordinate count differs from the vertex count");
        }
        if let Some(i) = self.positions.iter().position(|p| !p.is_finite()) {
            bail!("{name}: vertex {i} is not finite");
        }
        if self.indices.is_empty() {
            bail!("{name}: the mesh has no triangles");
        }
        Ok(self)
    }
}

/// An OBJ file's faces, triangulated as fans; texture coordinates flipped vertically when
/// `flip_tex_coords` (Mitsuba's default). Materials (`mtllib`) are not read: the XML's BSDF applies.
pub fn read_obj(path: &Path, flip_tex_coords: bool) -> Result<Mesh> {
    let name = path.display().to_string();
    let options = tobj::LoadOptions { single_index: true, triangulate: true, ignore_points: true, ignore_lines: true };
    let file = std::fs::File::open(path).map_err(|e| anyhow!("{name}: cannot read the mesh: {e}"))?;
    let mut reader = std::io::BufReader::new(file);
    let (models, _) = tobj::load_obj_buf(&mut reader, &options, |_| Ok(Default::default()))
        .map_err(|e| anyhow!("{name}: not a readable OBJ mesh: {e}"))?;
    let mut mesh = Mesh::default();
    let (mut normals, mut uvs) = (Vec::new(), Vec::new());
    let (mut all_normals, mut all_uvs) = (true, true);
    for model in &models {
        let m = &model.mesh;
        let base = mesh.positions.len() as u32;
        let count = m.positions.len() / 3;
        mesh.positions.extend(m.positions.chunks_exact(3).map(|p| Vec3::new(p[0], p[1], p[2])));
        all_normals &= m.normals.len() == 3 * count;
        all_uvs &= m.texcoords.len() == 2 * count;
        normals.extend(m.normals.chunks_exact(3).map(|n| Vec3::new(n[0], n[1], n[2]).normalize_or_zero()));
        let flip = |v: f32| if flip_tex_coords { 1.0 - v } else { v };
        uvs.extend(m.texcoords.chunks_exact(2).map(|t| Vec2::new(t[0], flip(t[1]))));
        mesh.indices.extend(m.indices.iter().map(|i| base + i));
    }
    mesh.normals = (all_normals && !normals.is_empty()).then_some(normals);
    mesh.uvs = (all_uvs && !uvs.is_empty()).then_some(uvs);
    mesh.checked(&name)
}

/// A PLY file's `vertex` (x, y, z; nx, ny, nz; u, v or s, t) and `face` (`vertex_indices` or
/// `vertex_index`, polygons as fans) elements, ASCII or binary.
pub fn read_ply(path: &Path) -> Result<Mesh> {
    use ply_rs_bw::ply::Property;
    let name = path.display().to_string();
    let file = std::fs::File::open(path).map_err(|e| anyhow!("{name}: cannot read the mesh: {e}"))?;
    let mut reader = std::io::BufReader::new(file);
    let ply = ply_rs_bw::parser::Parser::<ply_rs_bw::ply::DefaultElement>::new()
        .read_ply(&mut reader)
        .map_err(|e| anyhow!("{name}: not a readable PLY mesh: {e}"))?;
    let scalar = |p: &Property| -> Option<f64> {
        Some(match *p {
            Property::Char(x) => x as f64,
            Property::UChar(x) => x as f64,
            Property::Short(x) => x as f64,
            Property::UShort(x) => x as f64,
            Property::Int(x) => x as f64,
            Property::UInt(x) => x as f64,
            Property::Float(x) => x as f64,
            Property::Double(x) => x,
            _ => return None,
        })
    };
    let list = |p: &Property| -> Option<Vec<i64>> {
        Some(match p {
            Property::ListChar(v) => v.iter().map(|&x| x as i64).collect(),
            Property::ListUChar(v) => v.iter().map(|&x| x as i64).collect(),
            Property::ListShort(v) => v.iter().map(|&x| x as i64).collect(),
            Property::ListUShort(v) => v.iter().map(|&x| x as i64).collect(),
            Property::ListInt(v) => v.iter().map(|&x| x as i64).collect(),
            Property::ListUInt(v) => v.iter().map(|&x| x as i64).collect(),
            _ => return None,
        })
    };
    let vertices = ply.payload.get("vertex").ok_or_else(|| anyhow!("{name}: the PLY file has no `vertex` element"))?;
    let faces = ply.payload.get("face").ok_or_else(|| anyhow!("{name}: the PLY file has no `face` element"))?;
    let get3 = |v: &ply_rs_bw::ply::DefaultElement, keys: [&str; 3]| -> Option<Vec3> {
        let c: Option<Vec<f64>> = keys.iter().map(|k| v.get(*k).and_then(scalar)).collect();
        c.map(|c| Vec3::new(c[0] as f32, c[1] as f32, c[2] as f32))
    };
    let mut mesh = Mesh::default();
    for (i, v) in vertices.iter().enumerate() {
        let p = get3(v, ["x", "y", "z"]).ok_or_else(|| anyhow!("{name}: vertex {i} lacks x, y or z"))?;
        mesh.positions.push(p);
    }
    let normals: Option<Vec<Vec3>> =
        vertices.iter().map(|v| get3(v, ["nx", "ny", "nz"]).map(Vec3::normalize_or_zero)).collect();
    mesh.normals = normals;
    let uv_of = |v: &ply_rs_bw::ply::DefaultElement| -> Option<Vec2> {
        for (a, b) in [("u", "v"), ("s", "t"), ("texture_u", "texture_v"), ("texture_s", "texture_t")] {
            if let (Some(u), Some(w)) = (v.get(a).and_then(scalar), v.get(b).and_then(scalar)) {
                return Some(Vec2::new(u as f32, w as f32));
            }
        }
        None
    };
    mesh.uvs = vertices.iter().map(uv_of).collect();
    for (f, face) in faces.iter().enumerate() {
        let indices = face
            .get("vertex_indices")
            .or_else(|| face.get("vertex_index"))
            .and_then(list)
            .ok_or_else(|| anyhow!("{name}: face {f} has no vertex_indices list"))?;
        if indices.len() < 3 {
            bail!("{name}: face {f} has {} vertices (3 or more are needed)", indices.len());
        }
        if let Some(&bad) = indices.iter().find(|&&i| i < 0 || i as usize >= mesh.positions.len()) {
            bail!("{name}: face {f} names vertex {bad}, out of range ({} vertices)", mesh.positions.len());
        }
        for k in 1..indices.len() - 1 {
            mesh.indices.extend([indices[0] as u32, indices[k] as u32, indices[k + 1] as u32]);
        }
    }
    mesh.checked(&name)
}

/// Shape `index` of a Mitsuba `serialized` file: shapes one after the other, each a 16-bit
/// format tag 0x041C and version (3 or 4) and then a zlib stream holding flags, (version 4) a
/// name, the vertex and triangle counts and the arrays (positions, then as the flags say normals,
/// texture coordinates and colours, in f32 or f64, then 32- or 64-bit indices); the file ends
/// with the shapes' offsets (32-bit in version 3, 64-bit in 4) and their count (32-bit).
pub fn read_serialized(path: &Path, index: u32) -> Result<Mesh> {
    use std::io::Read as _;
    const TAG: u16 = 0x041C;
    const HAS_NORMALS: u32 = 0x0001;
    const HAS_TEXCOORDS: u32 = 0x0002;
    const HAS_COLORS: u32 = 0x0008;
    const FACE_NORMALS: u32 = 0x0010;
    const SINGLE: u32 = 0x1000;
    const DOUBLE: u32 = 0x2000;
    let name = path.display().to_string();
    let bytes = std::fs::read(path).map_err(|e| anyhow!("{name}: cannot read the mesh: {e}"))?;
    let bad = |what: &str| anyhow!("{name}: not a readable Mitsuba serialized mesh: {what}");
    let u16_at = |at: usize| bytes.get(at..at + 2).map(|b| u16::from_le_bytes([b[0], b[1]]));
    let u32_at = |at: usize| bytes.get(at..at + 4).map(|b| u32::from_le_bytes(b.try_into().expect("4 bytes")));
    let u64_at = |at: usize| bytes.get(at..at + 8).map(|b| u64::from_le_bytes(b.try_into().expect("8 bytes")));
    if u16_at(0) != Some(TAG) {
        return Err(bad("the file does not start with the format tag 0x041C"));
    }
    let version = u16_at(2).ok_or_else(|| bad("truncated"))?;
    if !matches!(version, 3 | 4) {
        return Err(bad(&format!("format version {version} (3 and 4 are read)")));
    }
    let count = bytes.len().checked_sub(4).and_then(u32_at).ok_or_else(|| bad("truncated"))?;
    if index >= count {
        bail!("{name}: shape_index {index}: the file holds {count} shape(s)");
    }
    let width = if version == 4 { 8 } else { 4 };
    let table = (bytes.len() - 4).checked_sub(count as usize * width).ok_or_else(|| bad("the offset table"))?;
    let at = table + index as usize * width;
    let offset = if version == 4 { u64_at(at) } else { u32_at(at).map(u64::from) }.ok_or_else(|| bad("the offsets"))?;
    let start = usize::try_from(offset).ok().filter(|&o| o + 4 <= table).ok_or_else(|| bad("an offset"))?;
    if u16_at(start) != Some(TAG) || u16_at(start + 2) != Some(version) {
        return Err(bad(&format!("shape {index} does not start with the format tag and version")));
    }
    let mut data = Vec::new();
    flate2::read::ZlibDecoder::new(&bytes[start + 4..table])
        .read_to_end(&mut data)
        .map_err(|e| bad(&format!("shape {index}'s zlib stream: {e}")))?;
    let mut stream = Stream { data: &data, at: 0 };
    let truncated = || bad(&format!("shape {index}'s data is truncated"));
    let flags = u32::from_le_bytes(stream.take(4).ok_or_else(truncated)?.try_into().expect("4 bytes"));
    if version == 4 {
        while stream.take(1).ok_or_else(truncated)?[0] != 0 {}
    }
    let vertices = u64::from_le_bytes(stream.take(8).ok_or_else(truncated)?.try_into().expect("8 bytes"));
    let triangles = u64::from_le_bytes(stream.take(8).ok_or_else(truncated)?.try_into().expect("8 bytes"));
    let real = match (flags & SINGLE != 0, flags & DOUBLE != 0) {
        (true, false) => 4,
        (false, true) => 8,
        _ => return Err(bad("neither single nor double precision")),
    };
    // Counts bounded by the data they claim, before any allocation.
    let per_vertex = real
        * (3 + 3 * (flags & HAS_NORMALS != 0) as usize
            + 2 * (flags & HAS_TEXCOORDS != 0) as usize
            + 3 * (flags & HAS_COLORS != 0) as usize);
    let index_width = if vertices > u32::MAX as u64 { 8 } else { 4 };
    let needed = (vertices as u128) * per_vertex as u128 + (triangles as u128) * 3 * index_width as u128;
    if needed > (data.len() - stream.at) as u128 {
        return Err(bad(&format!(
            "{vertices} vertices and {triangles} triangles need more data than the stream holds"
        )));
    }
    let mut reals = |n: usize| -> Result<Vec<f32>> {
        let b = stream.take(n * real).ok_or_else(truncated)?;
        Ok(if real == 4 {
            b.chunks_exact(4).map(|c| f32::from_le_bytes(c.try_into().expect("4 bytes"))).collect()
        } else {
            b.chunks_exact(8).map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes")) as f32).collect()
        })
    };
    let n = vertices as usize;
    let triple = |v: Vec<f32>| v.chunks_exact(3).map(|c| Vec3::new(c[0], c[1], c[2])).collect::<Vec<_>>();
    let positions = triple(reals(3 * n)?);
    let normals = if flags & HAS_NORMALS != 0 { Some(triple(reals(3 * n)?)) } else { None };
    let uvs = if flags & HAS_TEXCOORDS != 0 {
        Some(reals(2 * n)?.chunks_exact(2).map(|c| Vec2::new(c[0], c[1])).collect())
    } else {
        None
    };
    if flags & HAS_COLORS != 0 {
        reals(3 * n)?;
    }
    let ib = stream.take(triangles as usize * 3 * index_width).ok_or_else(truncated)?;
    let indices = if index_width == 4 {
        ib.chunks_exact(4).map(|c| u32::from_le_bytes(c.try_into().expect("4 bytes"))).collect()
    } else {
        let wide: Vec<u64> = ib.chunks_exact(8).map(|c| u64::from_le_bytes(c.try_into().expect("8 bytes"))).collect();
        wide.into_iter().map(|i| u32::try_from(i).unwrap_or(u32::MAX)).collect()
    };
    let normals =
        normals.filter(|_| flags & FACE_NORMALS == 0).map(|n| n.into_iter().map(Vec3::normalize_or_zero).collect());
    Mesh { positions, normals, uvs, indices }.checked(&name)
}

/// Bytes read one run after another.
struct Stream<'a> {
    data: &'a [u8],
    at: usize,
}

impl<'a> Stream<'a> {
    /// The next `n` bytes, or None past the end.
    fn take(&mut self, n: usize) -> Option<&'a [u8]> {
        let s = self.data.get(self.at..self.at.checked_add(n)?)?;
        self.at += n;
        Some(s)
    }
}

/// Mitsuba's `rectangle`: [-1, 1]^2 in the plane z = 0, facing +z.
pub fn rectangle() -> Mesh {
    Mesh {
        positions: vec![
            Vec3::new(-1.0, -1.0, 0.0),
            Vec3::new(1.0, -1.0, 0.0),
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(-1.0, 1.0, 0.0),
        ],
        normals: None,
        uvs: Some(vec![Vec2::new(0.0, 0.0), Vec2::new(1.0, 0.0), Vec2::new(1.0, 1.0), Vec2::new(0.0, 1.0)]),
        indices: vec![0, 1, 2, 2, 3, 0],
    }
}

/// Mitsuba's `cube`: [-1, 1]^3, faces outwards.
pub fn cube() -> Mesh {
    let mut mesh = Mesh { uvs: Some(Vec::new()), ..Default::default() };
    for axis in 0..3 {
        for sign in [-1.0f32, 1.0] {
            // The face's normal n, and two in-plane axes u, v with u x v = n.
            let n = Vec3::from_array(std::array::from_fn(|i| if i == axis { sign } else { 0.0 }));
            let u = Vec3::from_array(std::array::from_fn(|i| if i == (axis + 1) % 3 { 1.0 } else { 0.0 }));
            let v = n.cross(u);
            let base = mesh.positions.len() as u32;
            for (a, b) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
                mesh.positions.push(n + a * u + b * v);
                mesh.uvs.as_mut().expect("set above").push(Vec2::new(0.5 * (a + 1.0), 0.5 * (b + 1.0)));
            }
            mesh.indices.extend([base, base + 1, base + 2, base + 2, base + 3, base]);
        }
    }
    mesh
}

/// Segments around a circle so that a chord's sagitta is at most [`TESSELLATION_ERROR`] of the
/// radius: 1 - cos(pi / n) <= error.
fn circle_segments() -> u32 {
    (std::f32::consts::PI / (1.0 - TESSELLATION_ERROR).acos()).ceil() as u32
}

/// Radius of a regular n-gon whose area is the unit disk's: sqrt(pi / (n/2 sin(2 pi / n))).
fn area_preserving_polygon_radius(n: u32) -> f32 {
    let n = n as f64;
    (std::f64::consts::PI / (0.5 * n * (std::f64::consts::TAU / n).sin())).sqrt() as f32
}

/// Radius of a regular n-gon whose perimeter is the unit circle's: pi / (n sin(pi / n)).
fn perimeter_preserving_polygon_radius(n: u32) -> f32 {
    let n = n as f64;
    (std::f64::consts::PI / (n * (std::f64::consts::PI / n).sin())) as f32
}

/// Mitsuba's `disk`: the unit disk in the plane z = 0, facing +z, as a fan of the disk's area.
pub fn disk() -> Mesh {
    let n = circle_segments();
    let radius = area_preserving_polygon_radius(n);
    let mut mesh = Mesh { positions: vec![Vec3::ZERO], uvs: Some(vec![Vec2::ZERO]), ..Default::default() };
    for k in 0..n {
        let phi = std::f32::consts::TAU * k as f32 / n as f32;
        mesh.positions.push(Vec3::new(phi.cos(), phi.sin(), 0.0) * radius);
        mesh.uvs.as_mut().expect("set above").push(Vec2::new(1.0, k as f32 / n as f32));
        mesh.indices.extend([0, 1 + k, 1 + (k + 1) % n]);
    }
    mesh
}

/// Mitsuba's `cylinder`: the open tube of radius 1 about the z axis from z = 0 to 1, facing
/// outwards, of the tube's area, with normals of the true cylinder.
pub fn cylinder() -> Mesh {
    let n = circle_segments();
    let radius = perimeter_preserving_polygon_radius(n);
    let mut mesh = Mesh { normals: Some(Vec::new()), uvs: Some(Vec::new()), ..Default::default() };
    for k in 0..=n {
        let phi = std::f32::consts::TAU * k as f32 / n as f32;
        let radial = Vec3::new(phi.cos(), phi.sin(), 0.0);
        for z in [0.0, 1.0] {
            mesh.positions.push(radial * radius + Vec3::Z * z);
            mesh.normals.as_mut().expect("set above").push(radial);
            mesh.uvs.as_mut().expect("set above").push(Vec2::new(k as f32 / n as f32, z));
        }
    }
    for k in 0..n {
        let (a, b, c, d) = (2 * k, 2 * k + 1, 2 * k + 2, 2 * k + 3);
        mesh.indices.extend([a, c, d, d, b, a]);
    }
    mesh
}

/// Mitsuba's `sphere` of radius 1 about the origin, facing outwards: an icosahedron subdivided
/// until every triangle lies within [`TESSELLATION_ERROR`] of the sphere (a flat triangle is
/// farthest from it at its circumcentre, at most 1 - cos(e / sqrt 3) inside for a longest edge
/// of angle e), then scaled to the sphere's area, with the true sphere's normals.
pub fn sphere() -> Mesh {
    let t = (1.0 + 5f32.sqrt()) / 2.0;
    let mut positions: Vec<Vec3> = [
        (-1.0, t, 0.0),
        (1.0, t, 0.0),
        (-1.0, -t, 0.0),
        (1.0, -t, 0.0),
        (0.0, -1.0, t),
        (0.0, 1.0, t),
        (0.0, -1.0, -t),
        (0.0, 1.0, -t),
        (t, 0.0, -1.0),
        (t, 0.0, 1.0),
        (-t, 0.0, -1.0),
        (-t, 0.0, 1.0),
    ]
    .iter()
    .map(|&(x, y, z)| Vec3::new(x, y, z).normalize())
    .collect();
    let mut faces: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    let mut angle = positions[0].angle_between(positions[11]);
    while 1.0 - (angle / 3f32.sqrt()).cos() > TESSELLATION_ERROR {
        let mut midpoints = std::collections::HashMap::new();
        let mut midpoint = |a: u32, b: u32, positions: &mut Vec<Vec3>| -> u32 {
            *midpoints.entry((a.min(b), a.max(b))).or_insert_with(|| {
                positions.push((positions[a as usize] + positions[b as usize]).normalize());
                positions.len() as u32 - 1
            })
        };
        let mut next = Vec::with_capacity(faces.len() * 4);
        for [a, b, c] in faces {
            let (ab, bc, ca) =
                (midpoint(a, b, &mut positions), midpoint(b, c, &mut positions), midpoint(c, a, &mut positions));
            next.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        faces = next;
        // Subdivided edges are not all equal: bound by the longest.
        angle = faces
            .iter()
            .flat_map(|&[a, b, c]| [(a, b), (b, c), (c, a)])
            .fold(0.0f32, |m, (a, b)| m.max(positions[a as usize].angle_between(positions[b as usize])));
    }
    let uvs = positions
        .iter()
        .map(|p| {
            Vec2::new(p.y.atan2(p.x) / std::f32::consts::TAU + 0.5, p.z.clamp(-1.0, 1.0).acos() / std::f32::consts::PI)
        })
        .collect();
    let mut mesh = Mesh {
        normals: Some(positions.clone()),
        positions,
        uvs: Some(uvs),
        indices: faces.into_iter().flatten().collect(),
    };
    let radius = (4.0 * std::f64::consts::PI / mesh.area()).sqrt() as f32;
    mesh.positions.iter_mut().for_each(|p| *p *= radius);
    mesh
}

#[cfg(test)]
mod tests {
    use super::*;

    fn front_normals(mesh: &Mesh) -> impl Iterator<Item = (Vec3, Vec3)> + '_ {
        mesh.indices.chunks_exact(3).map(|t| {
            let [a, b, c] = [0, 1, 2].map(|k| mesh.positions[t[k] as usize]);
            ((b - a).cross(c - a).normalize(), (a + b + c) / 3.0)
        })
    }

    #[test]
    fn primitives_face_as_mitsuba_says() {
        for (n, _) in front_normals(&rectangle()).chain(front_normals(&disk())) {
            assert!(n.abs_diff_eq(Vec3::Z, 1e-6), "rectangle and disk face +z: {n}");
        }
        for (mesh, name) in [(cube(), "cube"), (sphere(), "sphere"), (cylinder(), "cylinder")] {
            for (n, centre) in front_normals(&mesh) {
                let out = if name == "cylinder" { Vec3::new(centre.x, centre.y, 0.0) } else { centre };
                assert!(n.dot(out) > 0.0, "{name} faces outwards");
            }
        }
    }

    #[test]
    fn curved_primitives_lie_within_the_stated_error() {
        let s = sphere();
        // The farthest point of a triangle from the sphere is near its centroid.
        let worst = front_normals(&s).map(|(_, c)| 1.0 - c.length()).fold(0.0f32, f32::max);
        assert!(worst <= TESSELLATION_ERROR, "sphere: {worst}");
        assert!(
            worst > 0.1 * TESSELLATION_ERROR,
            "sphere: not finer than needed ({worst}, {} triangles)",
            s.indices.len() / 3
        );
        let farthest_vertex = s.positions.iter().map(|p| (p.length() - 1.0).abs()).fold(0.0f32, f32::max);
        assert!(farthest_vertex <= TESSELLATION_ERROR, "sphere: vertices {farthest_vertex} off the sphere");
        let d = disk();
        let n = d.positions.len() - 1;
        let r = d.positions[1].length();
        let sagitta = 1.0 - r * (std::f32::consts::PI / n as f32).cos();
        assert!((r - 1.0).abs() <= TESSELLATION_ERROR, "disk: vertices at radius {r}");
        assert!(sagitta <= TESSELLATION_ERROR && sagitta > 0.1 * TESSELLATION_ERROR, "disk: {sagitta}");
        let c = cylinder();
        let r = Vec2::new(c.positions[0].x, c.positions[0].y).length();
        let sagitta = 1.0 - r * (std::f32::consts::PI / n as f32).cos();
        assert!((r - 1.0).abs() <= TESSELLATION_ERROR && sagitta <= TESSELLATION_ERROR, "cylinder: {r}, {sagitta}");
    }

    /// The meshes have the analytic shapes' areas (the light a surface reflects or emits is in
    /// proportion), to f32 rounding.
    #[test]
    fn curved_primitives_have_the_true_surfaces_areas() {
        let pi = std::f64::consts::PI;
        for (mesh, truth, name) in
            [(sphere(), 4.0 * pi, "sphere"), (disk(), pi, "disk"), (cylinder(), 2.0 * pi, "cylinder")]
        {
            let a = mesh.area();
            assert!((a / truth - 1.0).abs() < 2e-6, "{name}: area {a}, not {truth}");
        }
    }
}
