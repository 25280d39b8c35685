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
    /// The file's other vertex and face properties, as Mitsuba names them (`vertex_color`,
    /// `face_weight`, …), for `mesh_attribute` textures.
    pub attributes: Vec<Attribute>,
}

/// A mesh attribute of one or three channels (one is kept in all three).
#[derive(Clone, Debug)]
pub(crate) struct Attribute {
    /// `vertex_…` or `face_…`.
    pub name: String,
    /// One value per vertex, or per triangle for a face attribute (a polygon's value repeated
    /// for each triangle of its fan).
    pub values: Vec<Vec3A>,
}

impl Attribute {
    /// Whether it is given per face (per triangle) rather than per vertex.
    pub fn per_face(&self) -> bool {
        self.name.starts_with("face_")
    }

    /// Its values at the corners of triangle `i`, `t` (a face attribute's three times).
    pub fn corners(&self, i: usize, t: &[u32; 3]) -> [Vec3A; 3] {
        if self.per_face() {
            [self.values[i]; 3]
        } else {
            t.map(|v| self.values[v as usize])
        }
    }
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
        for a in &self.attributes {
            let n = if a.per_face() {
                self.triangles.len()
            } else {
                self.positions.len()
            };
            if a.values.len() != n {
                return Err(format!(
                    "attribute {} has {} values for {n} elements",
                    a.name,
                    a.values.len()
                ));
            }
            if a.values.iter().any(|v| !v.is_finite()) {
                return Err(format!("a value of attribute {} is not finite", a.name));
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
        attributes: Vec::new(),
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
/// are split into fans. Other vertex and face properties become [`Attribute`]s.
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
    // How many triangles each face became, for its attributes.
    let mut face_fans = Vec::new();
    for f in ply.payload.get("face").map(Vec::as_slice).unwrap_or_default() {
        let idx = f
            .get("vertex_indices")
            .or_else(|| f.get("vertex_index"))
            .and_then(Property::to_u32_list)
            .ok_or("a PLY face lacks a vertex_indices list")?;
        let before = mesh.triangles.len();
        for i in 1..idx.len().saturating_sub(1) {
            mesh.triangles.push([idx[0], idx[i], idx[i + 1]]);
        }
        face_fans.push(mesh.triangles.len() - before);
    }
    for (element, prefix, fans) in [("vertex", "vertex_", None), ("face", "face_", Some(&face_fans))] {
        let (Some(def), Some(items)) = (ply.header.elements.get(element), ply.payload.get(element)) else {
            continue;
        };
        let names: Vec<&str> = def.properties.keys().map(String::as_str).collect();
        for (name, channels) in attribute_groups(&names) {
            let values = items.iter().map(|e| {
                let c: Vec<f32> = channels
                    .iter()
                    .map(|k| e.get(*k).map_or(0.0, attribute_value))
                    .collect();
                if c.len() == 3 {
                    Vec3A::new(c[0], c[1], c[2])
                } else {
                    Vec3A::splat(c[0])
                }
            });
            let values = match fans {
                None => values.collect(),
                Some(fans) => values
                    .zip(fans.iter())
                    .flat_map(|(v, &n)| std::iter::repeat_n(v, n))
                    .collect(),
            };
            mesh.attributes.push(Attribute {
                name: format!("{prefix}{name}"),
                values,
            });
        }
    }
    Ok(mesh)
}

/// The properties a PLY element has beyond those read as geometry, grouped into attributes as
/// Mitsuba's PLY loader groups them: `r`, `g`, `b` (or `red`, `green`, `blue`) are `color`
/// (an alpha beside them is left out); consecutive `name_x name_y name_z` (or `_0 _1 _2`,
/// `_1 _2 _3`) are `name`, and `name_r name_g name_b` are `name_color`; one such property alone
/// is an attribute of one channel. As in Mitsuba, a group of two or four, a name without a
/// one-letter suffix, and a prefix seen before are left out.
fn attribute_groups<'a>(names: &[&'a str]) -> Vec<(String, Vec<&'a str>)> {
    const RESERVED: [&str; 19] = [
        "x",
        "y",
        "z",
        "nx",
        "ny",
        "nz",
        "u",
        "v",
        "s",
        "t",
        "texture_u",
        "texture_v",
        "vertex_indices",
        "vertex_index",
        "r",
        "g",
        "b",
        "a",
        "alpha",
    ];
    // Mitsuba's suffix sequences, by the suffix that starts them.
    const SEQUENCES: [[char; 4]; 4] = [
        ['x', 'y', 'z', 'w'],
        ['r', 'g', 'b', 'a'],
        ['0', '1', '2', '3'],
        ['1', '2', '3', '4'],
    ];
    let mut groups = Vec::new();
    for colour in [["r", "g", "b"], ["red", "green", "blue"]] {
        if colour.iter().all(|c| names.contains(c)) {
            groups.push(("color".to_string(), colour.to_vec()));
            break;
        }
    }
    let mut seen = std::collections::HashSet::new();
    // The group being read: its prefix, which sequence, and its members so far.
    type Open<'a> = Option<(&'a str, usize, Vec<&'a str>)>;
    fn close<'a>(open: &mut Open<'a>, groups: &mut Vec<(String, Vec<&'a str>)>) {
        if let Some((prefix, sequence, members)) = open.take()
            && (members.len() == 1 || members.len() == 3)
        {
            let name = if sequence == 1 {
                format!("{prefix}_color")
            } else {
                prefix.to_string()
            };
            groups.push((name, members));
        }
    }
    let mut open: Open<'a> = None;
    for &n in names {
        if RESERVED.contains(&n) || ["red", "green", "blue"].contains(&n) {
            continue;
        }
        let Some((prefix, suffix)) = n.rsplit_once('_').filter(|(_, s)| s.chars().count() == 1) else {
            close(&mut open, &mut groups);
            continue;
        };
        let c = suffix.chars().next().expect("one character");
        if let Some((current, sequence, members)) = &mut open
            && *current == prefix
        {
            if SEQUENCES[*sequence].get(members.len()) == Some(&c) {
                members.push(n);
            } else {
                // A broken sequence: Mitsuba ignores the attribute.
                open = None;
            }
            continue;
        }
        close(&mut open, &mut groups);
        if !seen.insert(prefix) {
            continue;
        }
        if let Some(sequence) = SEQUENCES.iter().position(|s| s[0] == c) {
            open = Some((prefix, sequence, vec![n]));
        }
    }
    close(&mut open, &mut groups);
    groups
}

/// A PLY property's value as an attribute: as it is, integers too (Mitsuba 3.9.1 neither
/// scales nor decodes 8-bit colours; it warns that they are expected in [0, 1]).
fn attribute_value(p: &ply_rs_bw::ply::Property) -> f32 {
    p.to_f32_lossy().unwrap_or(0.0)
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
        attributes: Vec::new(),
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
    fn ply_properties_group_into_attributes_as_in_mitsuba() {
        let groups = |names: &[&str]| -> Vec<(String, usize)> {
            attribute_groups(names)
                .into_iter()
                .map(|(n, m)| (n, m.len()))
                .collect()
        };
        let g = |v: &[(&str, usize)]| -> Vec<(String, usize)> {
            v.iter().map(|(n, c)| (n.to_string(), *c)).collect()
        };
        // mitsuba-data's sphere_attribute.ply.
        assert_eq!(
            groups(&[
                "x", "y", "z", "nx", "ny", "nz", "u", "v", "color_0", "color_1", "color_2"
            ]),
            g(&[("color", 3)])
        );
        assert_eq!(
            groups(&["vertex_indices", "color_0", "color_1", "color_2", "weight_0"]),
            g(&[("color", 3), ("weight", 1)])
        );
        assert_eq!(
            groups(&["x", "red", "green", "blue", "alpha"]),
            g(&[("color", 3)])
        );
        assert_eq!(
            groups(&["albedo_r", "albedo_g", "albedo_b"]),
            g(&[("albedo_color", 3)])
        );
        assert_eq!(groups(&["n_1", "n_2", "n_3", "k_x"]), g(&[("n", 3), ("k", 1)]));
        // Two or four channels, no suffix, a suffix out of sequence: left out.
        assert_eq!(
            groups(&["uv_x", "uv_y", "q_0", "q_1", "q_2", "q_3", "lone", "s_x", "s_z"]),
            g(&[])
        );
    }

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
