//! Mitsuba's named materials: dielectric indices of refraction and conductor presets.

use crate::color::Rgb;

/// Mitsuba 3's table of named indices of refraction (Hecht, Optics; at about 589 nm).
const IORS: &[(&str, f32)] = &[
    ("vacuum", 1.0),
    ("helium", 1.000036),
    ("hydrogen", 1.000132),
    ("air", 1.000277),
    ("carbon dioxide", 1.00045),
    ("water", 1.3330),
    ("acetone", 1.36),
    ("ethanol", 1.361),
    ("carbon tetrachloride", 1.461),
    ("glycerol", 1.4729),
    ("benzene", 1.501),
    ("silicone oil", 1.52045),
    ("bromine", 1.661),
    ("water ice", 1.31),
    ("fused quartz", 1.458),
    ("pyrex", 1.470),
    ("acrylic glass", 1.49),
    ("polypropylene", 1.49),
    ("bk7", 1.5046),
    ("sodium chloride", 1.544),
    ("amber", 1.55),
    ("pet", 1.5750),
    ("diamond", 2.419),
];

/// The index of refraction called `name`, case-insensitively.
pub(crate) fn ior(name: &str) -> Result<f32, String> {
    let lower = name.trim().to_ascii_lowercase();
    IORS.iter()
        .find(|(n, _)| *n == lower)
        .map(|(_, v)| *v)
        .ok_or_else(|| {
            let names: Vec<&str> = IORS.iter().map(|(n, _)| *n).collect();
            format!(
                "unknown index of refraction \"{name}\"; known: {}",
                names.join(", ")
            )
        })
}

/// Complex index (eta, k) of a named conductor, as Mitsuba 3.9 uses it in RGB mode.
pub(crate) fn conductor(name: &str) -> Result<(Rgb, Rgb), String> {
    if name == "none" {
        // A perfect mirror.
        return Ok((Rgb::ZERO, Rgb::ONE));
    }
    let table = include_str!("../../data/conductors.csv");
    for line in table.lines().filter(|l| !l.starts_with('#')).skip(1) {
        let cols: Vec<&str> = line.split(',').collect();
        if cols.len() == 7 && cols[0] == name {
            let v: Vec<f32> = cols[1..].iter().map(|c| c.parse().unwrap_or(f32::NAN)).collect();
            return Ok((Rgb::new(v[0], v[1], v[2]), Rgb::new(v[3], v[4], v[5])));
        }
    }
    let names: Vec<&str> = table
        .lines()
        .filter(|l| !l.starts_with('#'))
        .skip(1)
        .filter_map(|l| l.split(',').next())
        .collect();
    Err(format!(
        "unknown conductor \"{name}\"; known: none, {}",
        names.join(", ")
    ))
}

#[cfg(test)]
mod tests {
    #[test]
    fn lookups() {
        assert_eq!(super::ior("BK7").unwrap(), 1.5046);
        assert!(super::ior("unobtainium").is_err());
        let (eta, k) = super::conductor("Au").unwrap();
        assert!((eta.x - 0.143036).abs() < 1e-6 && (k.z - 1.603359).abs() < 1e-6);
        assert!(super::conductor("Xx").is_err());
    }
}
