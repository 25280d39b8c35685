//! Triangle meshes: Mitsuba's built-in rectangle, cube and disk, and OBJ and PLY files.

use std::f32::consts::PI;
use std::path::Path;

use glam::{Mat4, Vec3A};

/// An indexed triangle mesh in object or world space.
#[derive(Clone, Debug, Default)]
pub(crate) struct Mesh {
    pub positions: Vec<Vec3A>,
    /// Per-vertex normals, if the mesh has them (smooth shading).
    pub normals: Option<Vec<Vec3A>>,
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
        Ok(())
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
        triangles: vec![[0, 1, 2], [0, 2, 3]],
    }
}

/// [-1, 1]³ with outward faces.
pub(crate) fn cube() -> Mesh {
    let mut mesh = Mesh::default();
    for axis in 0..3 {
        for sign in [1.0f32, -1.0] {
            let n = Vec3A::AXES[axis] * sign;
            let (a, b) = (Vec3A::AXES[(axis + 1) % 3], Vec3A::AXES[(axis + 2) % 3]);
            // (u, v, n) right-handed, so that the winding faces outwards.
            let (u, v) = if sign > 0.0 { (a, b) } else { (b, a) };
            let base = mesh.positions.len() as u32;
            for (su, sv) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
                mesh.positions.push(n + su * u + sv * v);
            }
            mesh.triangles.push([base, base + 1, base + 2]);
            mesh.triangles.push([base, base + 2, base + 3]);
        }
    }
    mesh
}

/// The unit disk in the z = 0 plane, facing +z, as a fan of triangles whose total area is
/// exactly π (the rim radius is enlarged slightly to make up for the polygon's missing area).
pub(crate) fn disk() -> Mesh {
    const SEGMENTS: u32 = 256;
    let polygon_area = 0.5 * SEGMENTS as f32 * (2.0 * PI / SEGMENTS as f32).sin();
    let r = (PI / polygon_area).sqrt();
    let mut positions = vec![Vec3A::ZERO];
    for i in 0..SEGMENTS {
        let phi = 2.0 * PI * i as f32 / SEGMENTS as f32;
        positions.push(Vec3A::new(r * phi.cos(), r * phi.sin(), 0.0));
    }
    let triangles = (0..SEGMENTS)
        .map(|i| [0, 1 + i, 1 + (i + 1) % SEGMENTS])
        .collect();
    Mesh {
        positions,
        normals: None,
        triangles,
    }
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
    for v in vertices {
        let (Some(x), Some(y), Some(z)) = (scalar(v, "x"), scalar(v, "y"), scalar(v, "z")) else {
            return Err("a PLY vertex lacks x, y or z".into());
        };
        mesh.positions.push(Vec3A::new(x, y, z));
        if let (Some(nx), Some(ny), Some(nz)) = (scalar(v, "nx"), scalar(v, "ny"), scalar(v, "nz")) {
            normals.push(Vec3A::new(nx, ny, nz));
        }
    }
    if normals.len() == mesh.positions.len() && !normals.is_empty() {
        mesh.normals = Some(normals);
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
        // Every cube face points away from the centre.
        let c = cube();
        for t in &c.triangles {
            let [a, b, d] = t.map(|i| c.positions[i as usize]);
            let n = (b - a).cross(d - a);
            assert!(n.dot(a + b + d) > 0.0);
        }
    }
}
