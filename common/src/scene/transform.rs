//! `<transform>`: translate, rotate, scale, matrix and lookat, composed in Mitsuba's order
//! (each operation applies after the ones before it).

use glam::{Mat4, Vec3, Vec4};

use super::props::{Props, Res};
use super::xml::Element;

pub(crate) fn parse_transform(props: &Props, el: &Element) -> Res<Mat4> {
    let ctx = props.ctx;
    let mut m = Mat4::IDENTITY;
    for op in &el.children {
        let num = |k: &str, default: f32| -> Res<f32> {
            op.attr(k).map(|s| props.parse_f32(op, s)).unwrap_or(Ok(default))
        };
        let triple = |k: &str| -> Res<Option<Vec3>> {
            match op.attr(k) {
                Some(s) => match props.parse_list(op, s)?.as_slice() {
                    [x, y, z] => Ok(Some(Vec3::new(*x, *y, *z))),
                    _ => Err(ctx.err(op, format!("'{k}' needs three numbers"))),
                },
                None => Ok(None),
            }
        };
        let step = match op.tag.as_str() {
            "translate" => {
                let v = match triple("value")? {
                    Some(v) => v,
                    None => Vec3::new(num("x", 0.0)?, num("y", 0.0)?, num("z", 0.0)?),
                };
                Mat4::from_translation(v)
            }
            "rotate" => {
                let axis = match triple("axis")? {
                    Some(v) => v,
                    None => Vec3::new(num("x", 0.0)?, num("y", 0.0)?, num("z", 0.0)?),
                };
                if axis.length_squared() == 0.0 {
                    return Err(ctx.err(op, "rotation axis is zero"));
                }
                let angle = op
                    .attr("angle")
                    .ok_or_else(|| ctx.err(op, "missing the angle (degrees)"))?;
                let angle = props.parse_f32(op, angle)?;
                Mat4::from_axis_angle(axis.normalize(), angle.to_radians())
            }
            "scale" => {
                let s = match op.attr("value") {
                    Some(s) => match props.parse_list(op, s)?.as_slice() {
                        [u] => Vec3::splat(*u),
                        [x, y, z] => Vec3::new(*x, *y, *z),
                        _ => return Err(ctx.err(op, "scale value needs one or three numbers")),
                    },
                    None => Vec3::new(num("x", 1.0)?, num("y", 1.0)?, num("z", 1.0)?),
                };
                if s.x * s.y * s.z == 0.0 {
                    return Err(ctx.err(op, "scale by zero collapses the shape"));
                }
                Mat4::from_scale(s)
            }
            "matrix" => {
                let s = op
                    .attr("value")
                    .ok_or_else(|| ctx.err(op, "missing the value attribute"))?;
                let v = props.parse_list(op, s)?;
                let rows: [[f32; 4]; 4] = match v.len() {
                    16 => std::array::from_fn(|r| std::array::from_fn(|c| v[r * 4 + c])),
                    9 => std::array::from_fn(|r| {
                        std::array::from_fn(|c| match (r < 3, c < 3) {
                            (true, true) => v[r * 3 + c],
                            _ => (r == c) as u8 as f32,
                        })
                    }),
                    n => return Err(ctx.err(op, format!("a matrix needs 16 (or 9) numbers, got {n}"))),
                };
                // Mitsuba writes matrices row by row; glam stores columns.
                Mat4::from_cols_array_2d(&rows).transpose()
            }
            "lookat" => {
                let origin = triple("origin")?.ok_or_else(|| ctx.err(op, "missing origin"))?;
                let target = triple("target")?.ok_or_else(|| ctx.err(op, "missing target"))?;
                // Mitsuba: with no (or a zero) up, the first tangent of Duff et al.'s basis
                // around the view direction.
                let up = match triple("up")? {
                    Some(up) if up != Vec3::ZERO => up,
                    _ => {
                        let dir = crate::geometry::Frame::from_normal((target - origin).normalize().into());
                        Vec3::from(dir.s)
                    }
                };
                look_at(origin, target, up).ok_or_else(|| {
                    ctx.err(
                        op,
                        "degenerate lookat: origin equals target, or up is parallel to the view",
                    )
                })?
            }
            other => return Err(ctx.err(op, format!("unknown transform operation <{other}>"))),
        };
        m = step * m;
    }
    if !m.is_finite() {
        return Err(ctx.err(el, "the transform is not finite"));
    }
    Ok(m)
}

/// Mitsuba's look-at: columns (left, up, forward, origin).
fn look_at(origin: Vec3, target: Vec3, up: Vec3) -> Option<Mat4> {
    let dir = (target - origin).try_normalize()?;
    let left = up.cross(dir).try_normalize()?;
    let new_up = dir.cross(left);
    Some(Mat4::from_cols(
        left.extend(0.0),
        new_up.extend(0.0),
        dir.extend(0.0),
        Vec4::new(origin.x, origin.y, origin.z, 1.0),
    ))
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use crate::scene::Scene;

    /// A `lookat` without `up`: Mitsuba builds one from the view direction. The expected matrix
    /// is Mitsuba 3.9.1's (scalar_rgb) `world_transform()` of the same sensor.
    #[test]
    fn lookat_without_up_matches_mitsuba() {
        let text = r#"<scene version="3.0.0"><sensor type="perspective">
            <transform name="to_world"><lookat origin="1, 2, 5" target="0, 0.5, 0"/></transform>
            <film type="hdrfilm"><integer name="width" value="4"/><integer name="height" value="4"/></film>
            </sensor></scene>"#;
        let scene = Scene::from_str(text, Path::new("t.xml"), &[]).unwrap();
        let m = scene.camera.to_world.to_cols_array_2d();
        let mitsuba = [
            [-0.0273596, 0.98176, -0.188144, 1.0],
            [0.958961, -0.0273596, -0.282216, 2.0],
            [-0.282216, -0.188144, -0.940721, 5.0],
        ];
        for (row, want) in mitsuba.iter().enumerate() {
            for (col, w) in want.iter().enumerate() {
                assert!(
                    (m[col][row] - w).abs() < 1e-5,
                    "row {row} col {col}: {} vs {w}",
                    m[col][row]
                );
            }
        }
    }
}
