//! Mitsuba's curve files (`linearcurve`, `bsplinecurve`): one control point per line as
//! "x y z radius", curves separated by empty lines.

/// One curve's control points: (position, radius).
pub type Curve = Vec<([f32; 3], f32)>;

/// Longest line Mitsuba reads (it refuses longer ones).
const MAX_LINE: usize = 1024;

/// Parses a curve file: the curves, each of at least `min_points` control points, or a message
/// naming the line.
pub fn parse(text: &str, min_points: usize) -> Result<Vec<Curve>, String> {
    let mut curves: Vec<Curve> = Vec::new();
    let mut current: Curve = Vec::new();
    let mut finish = |current: &mut Curve, line: usize| {
        if current.is_empty() {
            return Ok(());
        }
        if current.len() < min_points {
            return Err(format!(
                "the curve ending at line {line} has {} control point(s); a curve needs at least {min_points}",
                current.len()
            ));
        }
        curves.push(std::mem::take(current));
        Ok(())
    };
    for (i, line) in text.lines().enumerate() {
        let n = i + 1;
        if line.len() > MAX_LINE {
            return Err(format!("line {n} is longer than {MAX_LINE} characters"));
        }
        let fields: Vec<&str> = line.split_whitespace().collect();
        if fields.is_empty() {
            finish(&mut current, n)?;
            continue;
        }
        let values: Vec<f32> = fields
            .iter()
            .map(|f| f.parse::<f32>())
            .collect::<Result<_, _>>()
            .map_err(|_| format!("line {n}: expected \"x y z radius\", got \"{line}\""))?;
        let [x, y, z, r] = values[..] else {
            return Err(format!(
                "line {n}: expected four numbers (x y z radius), got {}",
                values.len()
            ));
        };
        if !values.iter().all(|v| v.is_finite()) || r < 0.0 {
            return Err(format!(
                "line {n}: a control point needs finite numbers and a radius of at least 0"
            ));
        }
        current.push(([x, y, z], r));
    }
    finish(&mut current, text.lines().count())?;
    if curves.is_empty() {
        return Err("no control points".into());
    }
    Ok(curves)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn curves_are_separated_by_empty_lines() {
        let c = parse(
            "-1 0.1 0.1 0.5\n1 1.4 1.2 0.5\n\n  \n-1 5 2.2 1\n-2.3 4 2.3 2\n4 1 2.2 5\n",
            2,
        )
        .unwrap();
        assert_eq!(c.len(), 2);
        assert_eq!(c[0].len(), 2);
        assert_eq!(c[1][2], ([4.0, 1.0, 2.2], 5.0));
        assert!(
            parse("0 0 0 1\n\n1 1 1 1\n2 2 2 1\n", 2)
                .unwrap_err()
                .contains("at least 2")
        );
        assert!(parse("0 0 0\n1 1 1\n", 2).unwrap_err().contains("four numbers"));
        assert!(parse("0 0 zero 1\n", 2).unwrap_err().contains("line 1"));
        assert!(parse("0 0 0 -1\n1 0 0 1\n", 2).unwrap_err().contains("radius"));
        assert!(parse("\n\n", 2).unwrap_err().contains("no control points"));
    }
}
