//! Triangle meshes: Mitsuba's built-in rectangle, cube and disk, and OBJ, PLY and Mitsuba's
//! `serialized` files.

use std::f32::consts::PI;
use std::path::Path;

use glam::{Mat4, Vec2, Vec3A};

/// An indexed triangle mesh in object or world space.
#[derive(Clone, Debug, Default)]
pub(crate) struct Mesh {
    pub positions: Vec<Vec3A>,
    /// Per-vertex normals, if the mesh has them (smooth shading).
    pub normals: Option<Vec<Vec3A>>,
    /// Per-vertex texture coordinates, if the mesh has them.
    pub uvs: Option<Vec<Vec2>>,
    pub triangles: Vec<[u32; 3]>,
}

impl Mesh {
    /// Applies `m` to positions, and its inverse transpose to normals.
    pub fn transformed(mut self, m: &Mat4) -> Mesh {
        for p in &mut self.positions {
            *p = m.transform_point3a(*p);
        }
        if let Some(ns) = &mut self.normals {
            let nm = m.inverse().transpose();
            for n in ns.iter_mut() {
                *n = nm.transform_vector3a(*n).normalize_or_zero();
            }
        }
        self
    }

    /// Turns every triangle over: its geometric normal (the cross product of its edges) flips.
    pub fn reverse_winding(&mut self) {
        for t in &mut self.triangles {
            t.swap(1, 2);
        }
    }

    /// Smooth vertex normals for a mesh file that has none, as Mitsuba computes them (in world
    /// space): each face's normal weighted by its angle at the vertex (Thürmer and Wüthrich).
    /// Without them a curved mesh would look faceted in ours and smooth in Mitsuba.
    pub fn recompute_vertex_normals(&mut self) {
        let mut normals = vec![Vec3A::ZERO; self.positions.len()];
        for t in &self.triangles {
            let v = t.map(|i| self.positions[i as usize]);
            let n = (v[1] - v[0]).cross(v[2] - v[0]);
            if n.length_squared() <= 0.0 || !n.is_finite() {
                continue;
            }
            let n = n.normalize();
            for j in 0..3 {
                let (a, b) = (
                    (v[(j + 1) % 3] - v[j]).normalize(),
                    (v[(j + 2) % 3] - v[j]).normalize(),
                );
                normals[t[j] as usize] += n * libm::acosf(a.dot(b).clamp(-1.0, 1.0));
            }
        }
        for n in &mut normals {
            // Mitsuba's stand-in for a vertex no face defines a normal at.
            *n = n.try_normalize().unwrap_or(Vec3A::X);
        }
        self.normals = Some(normals);
    }

    /// Index and value checks, so that a broken file fails at load and not in the renderer.
    pub fn validate(&self) -> Result<(), String> {
        let n = self.positions.len() as u32;
        if let Some(t) = self.triangles.iter().find(|t| t.iter().any(|&i| i >= n)) {
            return Err(format!(
                "a face refers to vertex {} but there are only {n}",
                t.iter().max().unwrap()
            ));
        }
        if self.positions.iter().any(|p| !p.is_finite()) {
            return Err("a vertex position is not finite".into());
        }
        if let Some(ns) = &self.normals
            && ns.len() != self.positions.len()
        {
            return Err("the number of normals differs from the number of vertices".into());
        }
        if let Some(uvs) = &self.uvs {
            if uvs.len() != self.positions.len() {
                return Err("the number of texture coordinates differs from the number of vertices".into());
            }
            if uvs.iter().any(|uv| !uv.is_finite()) {
                return Err("a texture coordinate is not finite".into());
            }
        }
        Ok(())
    }

    /// Mirrors the texture coordinates' v (Mitsuba's `flip_tex_coords`).
    pub fn flip_tex_coords(&mut self) {
        for uv in self.uvs.iter_mut().flatten() {
            uv.y = 1.0 - uv.y;
        }
    }
}

/// [-1, 1]² in the z = 0 plane, facing +z.
pub(crate) fn rectangle() -> Mesh {
    Mesh {
        positions: vec![
            Vec3A::new(-1.0, -1.0, 0.0),
            Vec3A::new(1.0, -1.0, 0.0),
            Vec3A::new(1.0, 1.0, 0.0),
            Vec3A::new(-1.0, 1.0, 0.0),
        ],
        normals: None,
        uvs: Some(vec![
            Vec2::new(0.0, 0.0),
            Vec2::new(1.0, 0.0),
            Vec2::new(1.0, 1.0),
            Vec2::new(0.0, 1.0),
        ]),
        triangles: vec![[0, 1, 2], [0, 2, 3]],
    }
}

/// [-1, 1]³ with outward faces, with Mitsuba's texture coordinates on each face.
pub(crate) fn cube() -> Mesh {
    let mut mesh = Mesh::default();
    let mut uvs = Vec::new();
    for axis in 0..3 {
        for sign in [1.0f32, -1.0] {
            let n = Vec3A::AXES[axis] * sign;
            let (a, b) = (Vec3A::AXES[(axis + 1) % 3], Vec3A::AXES[(axis + 2) % 3]);
            // (u, v, n) right-handed, so that the winding faces outwards.
            let (u, v) = if sign > 0.0 { (a, b) } else { (b, a) };
            let base = mesh.positions.len() as u32;
            for (su, sv) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
                let p = n + su * u + sv * v;
                mesh.positions.push(p);
                uvs.push(cube_uv(axis, sign, p));
            }
            mesh.triangles.push([base, base + 1, base + 2]);
            mesh.triangles.push([base, base + 2, base + 3]);
        }
    }
    mesh.uvs = Some(uvs);
    mesh
}

/// Mitsuba's (u, v) on the cube face with normal `sign` along `axis`, at `p`: each face's
/// coordinates are affine in the position (read off its `cube` shape's 24 vertices).
fn cube_uv(axis: usize, sign: f32, p: Vec3A) -> Vec2 {
    let h = |x: f32| (x + 1.0) * 0.5;
    let (x, y, z) = (p.x, p.y, p.z);
    match (axis, sign > 0.0) {
        (1, false) => Vec2::new(h(z), h(x)),
        (1, true) => Vec2::new(h(-x), h(-z)),
        (0, true) => Vec2::new(h(y), h(-z)),
        (2, true) => Vec2::new(h(y), h(x)),
        (0, false) => Vec2::new(h(y), h(z)),
        _ => Vec2::new(h(-y), h(x)),
    }
}

/// The unit disk in the z = 0 plane, facing +z, as a fan of triangles whose total area is
/// exactly π (the rim radius is enlarged slightly to make up for the polygon's missing area).
/// Texture coordinates are Mitsuba's (radius, angle / 2π); each triangle has its own vertices,
/// so that the angle does not jump inside the last one.
pub(crate) fn disk() -> Mesh {
    const SEGMENTS: u32 = 256;
    let polygon_area = 0.5 * SEGMENTS as f32 * libm::sinf(2.0 * PI / SEGMENTS as f32);
    let r = (PI / polygon_area).sqrt();
    let mut mesh = Mesh::default();
    let mut uvs = Vec::new();
    let rim = |i: u32| {
        let phi = 2.0 * PI * (i % SEGMENTS) as f32 / SEGMENTS as f32;
        let (sin_phi, cos_phi) = libm::sincosf(phi);
        Vec3A::new(r * cos_phi, r * sin_phi, 0.0)
    };
    for i in 0..SEGMENTS {
        let (t0, t1) = (i as f32 / SEGMENTS as f32, (i + 1) as f32 / SEGMENTS as f32);
        let base = mesh.positions.len() as u32;
        mesh.positions.extend([Vec3A::ZERO, rim(i), rim(i + 1)]);
        uvs.extend([
            Vec2::new(0.0, 0.5 * (t0 + t1)),
            Vec2::new(1.0, t0),
            Vec2::new(1.0, t1),
        ]);
        mesh.triangles.push([base, base + 1, base + 2]);
    }
    mesh.uvs = Some(uvs);
    mesh
}

/// A Wavefront OBJ file (all its objects as one mesh), triangulated.
pub(crate) fn load_obj(path: &Path) -> Result<Mesh, String> {
    let opts = tobj::LoadOptions {
        triangulate: true,
        single_index: true,
        ..Default::default()
    };
    let (models, _materials) = tobj::load_obj(path, &opts).map_err(|e| format!("cannot read OBJ: {e}"))?;
    let mut mesh = Mesh::default();
    let mut normals = Vec::new();
    let mut all_have_normals = true;
    let mut uvs = Vec::new();
    let mut all_have_uvs = true;
    for m in models {
        let base = mesh.positions.len() as u32;
        let pos = &m.mesh.positions;
        mesh.positions
            .extend(pos.chunks_exact(3).map(|c| Vec3A::new(c[0], c[1], c[2])));
        if m.mesh.normals.len() == pos.len() {
            normals.extend(
                m.mesh
                    .normals
                    .chunks_exact(3)
                    .map(|c| Vec3A::new(c[0], c[1], c[2])),
            );
        } else {
            all_have_normals = false;
        }
        if m.mesh.texcoords.len() / 2 == pos.len() / 3 {
            uvs.extend(m.mesh.texcoords.chunks_exact(2).map(|c| Vec2::new(c[0], c[1])));
        } else {
            all_have_uvs = false;
        }
        mesh.triangles.extend(
            m.mesh
                .indices
                .chunks_exact(3)
                .map(|c| [base + c[0], base + c[1], base + c[2]]),
        );
    }
    if all_have_normals && !normals.is_empty() {
        mesh.normals = Some(normals);
    }
    if all_have_uvs && !uvs.is_empty() {
        mesh.uvs = Some(uvs);
    }
    Ok(mesh)
}

/// A PLY file (ASCII or binary): vertices with x, y, z and optional nx, ny, nz; polygonal faces
/// are split into fans.
pub(crate) fn load_ply(path: &Path) -> Result<Mesh, String> {
    use ply_rs_bw::parser::Parser;
    use ply_rs_bw::ply::{DefaultElement, Property};
    let file = std::fs::File::open(path).map_err(|e| format!("cannot open PLY: {e}"))?;
    let mut reader = std::io::BufReader::new(file);
    let ply = Parser::<DefaultElement>::new()
        .read_ply(&mut reader)
        .map_err(|e| format!("cannot read PLY: {e}"))?;
    let scalar = |e: &DefaultElement, k: &str| e.get(k).and_then(Property::to_f32_lossy);
    let vertices = ply
        .payload
        .get("vertex")
        .ok_or("PLY file has no vertex element")?;
    let mut mesh = Mesh::default();
    let mut normals = Vec::with_capacity(vertices.len());
    let mut uvs = Vec::with_capacity(vertices.len());
    for v in vertices {
        let (Some(x), Some(y), Some(z)) = (scalar(v, "x"), scalar(v, "y"), scalar(v, "z")) else {
            return Err("a PLY vertex lacks x, y or z".into());
        };
        mesh.positions.push(Vec3A::new(x, y, z));
        if let (Some(nx), Some(ny), Some(nz)) = (scalar(v, "nx"), scalar(v, "ny"), scalar(v, "nz")) {
            normals.push(Vec3A::new(nx, ny, nz));
        }
        // Mitsuba's names for texture coordinates.
        if let Some((u, v)) = [("u", "v"), ("texture_u", "texture_v"), ("s", "t")]
            .into_iter()
            .find_map(|(name_u, name_v)| Some((scalar(v, name_u)?, scalar(v, name_v)?)))
        {
            uvs.push(Vec2::new(u, v));
        }
    }
    if normals.len() == mesh.positions.len() && !normals.is_empty() {
        mesh.normals = Some(normals);
    }
    if uvs.len() == mesh.positions.len() && !uvs.is_empty() {
        mesh.uvs = Some(uvs);
    }
    for f in ply.payload.get("face").map(Vec::as_slice).unwrap_or_default() {
        let idx = f
            .get("vertex_indices")
            .or_else(|| f.get("vertex_index"))
            .and_then(Property::to_u32_list)
            .ok_or("a PLY face lacks a vertex_indices list")?;
        for i in 1..idx.len().saturating_sub(1) {
            mesh.triangles.push([idx[0], idx[i], idx[i + 1]]);
        }
    }
    Ok(mesh)
}

/// Mesh `shape_index` of a Mitsuba `serialized` file (format versions 3 and 4): each mesh is a
/// 0x041C header, a version and a zlib stream; a table of mesh offsets ends the file.
pub(crate) fn load_serialized(path: &Path, shape_index: u32) -> Result<Mesh, String> {
    use std::io::Read;
    let bytes = std::fs::read(path).map_err(|e| format!("cannot read: {e}"))?;
    let u16_at = |o: usize| bytes.get(o..o + 2).map(|b| u16::from_le_bytes([b[0], b[1]]));
    let u32_at = |o: usize| {
        bytes
            .get(o..o + 4)
            .map(|b| u32::from_le_bytes(b.try_into().unwrap()))
    };
    let u64_at = |o: usize| {
        bytes
            .get(o..o + 8)
            .map(|b| u64::from_le_bytes(b.try_into().unwrap()))
    };
    let bad = || "not a Mitsuba serialized mesh (truncated or damaged)".to_string();
    let (magic, version) = (u16_at(0).ok_or_else(bad)?, u16_at(2).ok_or_else(bad)?);
    if magic != 0x041C {
        return Err("not a Mitsuba serialized mesh (its header is not 0x041C)".into());
    }
    if !matches!(version, 3 | 4) {
        return Err(format!(
            "serialized format version {version} is not supported (3, 4)"
        ));
    }
    let count = u32_at(bytes.len().checked_sub(4).ok_or_else(bad)?).ok_or_else(bad)?;
    if shape_index >= count {
        return Err(format!(
            "shape_index {shape_index} is out of range: the file holds {count} meshes"
        ));
    }
    let offset = if shape_index == 0 {
        0
    } else if version == 4 {
        let at = bytes.len() - 4 - 8 * (count - shape_index) as usize;
        u64_at(at).ok_or_else(bad)? as usize
    } else {
        let at = bytes.len() - 4 * (count - shape_index + 1) as usize;
        u32_at(at).ok_or_else(bad)? as usize
    };
    if u16_at(offset) != Some(0x041C) {
        return Err(bad());
    }
    let stream = bytes.get(offset + 4..).ok_or_else(bad)?;
    let mut data = Vec::new();
    flate2::read::ZlibDecoder::new(stream)
        .read_to_end(&mut data)
        .map_err(|e| format!("cannot decompress mesh {shape_index}: {e}"))?;
    let mut r = Cursor { data: &data, at: 0 };
    let flags = r.u32()?;
    if version == 4 {
        // The shape's name, NUL-terminated.
        while r.bytes(1)?[0] != 0 {}
    }
    let (vertices, faces) = (r.u64()? as usize, r.u64()? as usize);
    let double = flags & 0x2000 != 0;
    // Each count must fit in what was decompressed before anything is allocated for it.
    let scalar = if double { 8 } else { 4 };
    let per_vertex = scalar
        * (3 + 3 * (flags & 1 != 0) as usize + 2 * (flags & 2 != 0) as usize + 3 * (flags & 8 != 0) as usize);
    let need = vertices
        .checked_mul(per_vertex)
        .and_then(|v| v.checked_add(faces.checked_mul(12)?));
    if need.is_none_or(|n| n > data.len() - r.at) {
        return Err(format!("mesh {shape_index} claims more data than the file holds"));
    }
    let vec3s = |r: &mut Cursor| -> Result<Vec<Vec3A>, String> {
        (0..vertices)
            .map(|_| Ok(Vec3A::new(r.real(double)?, r.real(double)?, r.real(double)?)))
            .collect()
    };
    let positions = vec3s(&mut r)?;
    let normals = if flags & 1 != 0 {
        Some(vec3s(&mut r)?)
    } else {
        None
    };
    let uvs = if flags & 2 != 0 {
        Some(
            (0..vertices)
                .map(|_| Ok(Vec2::new(r.real(double)?, r.real(double)?)))
                .collect::<Result<Vec<_>, String>>()?,
        )
    } else {
        None
    };
    if flags & 8 != 0 {
        r.bytes(3 * scalar * vertices)?; // vertex colours: Mitsuba drops them too
    }
    let triangles = (0..faces)
        .map(|_| Ok([r.u32()?, r.u32()?, r.u32()?]))
        .collect::<Result<Vec<_>, String>>()?;
    Ok(Mesh {
        positions,
        normals,
        uvs,
        triangles,
    })
}

/// Reads little-endian values from a decompressed mesh.
struct Cursor<'a> {
    data: &'a [u8],
    at: usize,
}

impl Cursor<'_> {
    fn bytes(&mut self, n: usize) -> Result<&[u8], String> {
        let b = self
            .data
            .get(self.at..self.at.checked_add(n).ok_or("mesh data overflow")?)
            .ok_or("the mesh data ends early")?;
        self.at += n;
        Ok(b)
    }
    fn u32(&mut self) -> Result<u32, String> {
        Ok(u32::from_le_bytes(self.bytes(4)?.try_into().unwrap()))
    }
    fn u64(&mut self) -> Result<u64, String> {
        Ok(u64::from_le_bytes(self.bytes(8)?.try_into().unwrap()))
    }
    fn real(&mut self, double: bool) -> Result<f32, String> {
        Ok(if double {
            f64::from_le_bytes(self.bytes(8)?.try_into().unwrap()) as f32
        } else {
            f32::from_le_bytes(self.bytes(4)?.try_into().unwrap())
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn built_in_shapes_have_mitsubas_areas_and_orientation() {
        let area = |m: &Mesh| -> f32 {
            m.triangles
                .iter()
                .map(|t| {
                    let [a, b, c] = t.map(|i| m.positions[i as usize]);
                    0.5 * (b - a).cross(c - a).length()
                })
                .sum()
        };
        assert!((area(&rectangle()) - 4.0).abs() < 1e-5);
        assert!((area(&cube()) - 24.0).abs() < 1e-4);
        assert!((area(&disk()) - PI).abs() < 1e-4);
        // Mitsuba's cube: a vertex of each face with its (u, v).
        for (p, n, uv) in [
            ((1.0, -1.0, 1.0), 0, (1.0, 1.0)),
            ((-1.0, 1.0, -1.0), 1, (1.0, 1.0)),
            ((1.0, 1.0, 1.0), 2, (1.0, 0.0)),
            ((-1.0, 1.0, 1.0), 3, (1.0, 0.0)),
            ((-1.0, 1.0, -1.0), 4, (1.0, 0.0)),
            ((-1.0, -1.0, -1.0), 5, (1.0, 0.0)),
            ((1.0, -1.0, -1.0), 0, (0.0, 1.0)),
            ((1.0, 1.0, 1.0), 1, (0.0, 0.0)),
            ((1.0, -1.0, 1.0), 3, (0.0, 1.0)),
            ((1.0, 1.0, -1.0), 5, (0.0, 1.0)),
        ] {
            let p = Vec3A::new(p.0, p.1, p.2);
            // Face n of Mitsuba's table: -y, +y, +x, +z, -x, -z.
            let (axis, sign) = [(1, -1.0), (1, 1.0), (0, 1.0), (2, 1.0), (0, -1.0), (2, -1.0)][n];
            assert_eq!(cube_uv(axis, sign, p), Vec2::new(uv.0, uv.1), "face {n} at {p}");
        }
        // Every cube face points away from the centre.
        let c = cube();
        for t in &c.triangles {
            let [a, b, d] = t.map(|i| c.positions[i as usize]);
            let n = (b - a).cross(d - a);
            assert!(n.dot(a + b + d) > 0.0);
        }
    }
}
