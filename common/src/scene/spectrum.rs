//! `<spectrum>` values given as `wavelength:value` lists or `.spd` files, turned into the linear
//! sRGB colour that Mitsuba 3's RGB variants give them.
//!
//! We render in RGB only, so a spectrum has to become one colour when the scene is loaded. To
//! render what Mitsuba renders, that colour must be the one Mitsuba computes, including its
//! quirks: it integrates with 1000 samples over 360–830 nm, treats the spectrum as zero outside
//! its listed wavelengths, weights by D65 unless the spectrum is emitted, and clips the result.
//!
//! The CIE 1931 2° colour-matching functions and the D65 illuminant come from
//! `common/data/cie1931-d65.csv` (CIE 15:2004 tables, via the colour-science and luxpy packages;
//! the file's first line names the sources). Mitsuba's tables are the same numbers, held as
//! float32, so we round them to `f32` too and compute everything else in `f64` as Mitsuba does.

use std::path::Path;
use std::sync::OnceLock;

use crate::color::Rgb;

/// What a spectrum is used for: it decides Mitsuba's conversion.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum SpectrumUse {
    /// Reflectance-like parameters (Mitsuba's `get_texture`): a colour must stay in [0, 1].
    Reflectance,
    /// Parameters that may exceed 1 (`get_unbounded_texture`: conductor `eta`/`k`, roughness,
    /// medium coefficients). Mitsuba still weights them by D65, as for reflectance.
    Unbounded,
    /// Emitted radiance, intensity or irradiance (`get_emissive_texture`): an emitter's spectrum
    /// is the light itself, so Mitsuba does not weight it by the D65 white point.
    Emission,
}

/// The CIE table, embedded so that a scene converts the same on every machine of a farm.
const CIE_CSV: &str = include_str!("../../data/cie1931-d65.csv");

/// The tables' wavelength range and sample count (5 nm steps), as in Mitsuba.
const CIE_MIN: f64 = 360.0;
const CIE_MAX: f64 = 830.0;
const CIE_SAMPLES: usize = 95;

/// Scales the colour-matching functions so that a spectrum of 1 has luminance 1: Mitsuba's
/// `MI_CIE_Y_NORMALIZATION`, which the sum must use as is for the colours to agree.
const Y_NORMALIZATION: f64 = 1.0 / 106.750_259_399_414_06;

/// Scales D65 so that its luminance is 1 (Mitsuba's `MI_CIE_D65_NORMALIZATION`): a reflectance
/// of 1 then gives white.
const D65_NORMALIZATION: f64 = 1.0 / 98.997_417_518_762_55;

/// Mitsuba integrates every list with this many evenly spaced samples, whatever its own spacing.
const STEPS: usize = 1000;

/// CIE XYZ to linear sRGB (Rec. 709 primaries, D65 white). These are Mitsuba's float32
/// constants, so the `f64` arithmetic matches its double-precision path to the last bits.
const XYZ_TO_SRGB: [[f32; 3]; 3] = [
    [3.240_479, -1.537_15, -0.498_535],
    [-0.969_256, 1.875_991, 0.041_556],
    [0.055_648, -0.204_043, 1.057_311],
];

/// The colour-matching functions and D65 at 360, 365, …, 830 nm, in `f32` because Mitsuba
/// stores them so and rounding them differently would shift colours in the last digits.
struct CieTables {
    /// x̄, ȳ and z̄.
    xyz: [[f32; CIE_SAMPLES]; 3],
    /// D65, relative power, 100 at 560 nm.
    d65: [f32; CIE_SAMPLES],
}

/// The tables, parsed on first use: the embedded file is ours, so a malformed one is a bug.
fn tables() -> &'static CieTables {
    static TABLES: OnceLock<CieTables> = OnceLock::new();
    TABLES.get_or_init(|| match parse_tables(CIE_CSV) {
        Ok(tables) => tables,
        Err(message) => panic!("common/data/cie1931-d65.csv: {message}"),
    })
}

/// Reads the CSV: `#` comment lines, a header, then one row per 5 nm from 360 to 830 nm.
fn parse_tables(text: &str) -> Result<CieTables, String> {
    let mut lines = text
        .lines()
        .enumerate()
        .filter(|(_, line)| !line.trim().is_empty() && !line.starts_with('#'));
    match lines.next() {
        Some((_, header)) if header.trim() == "nm,xbar,ybar,zbar,d65" => {}
        other => {
            return Err(format!(
                "expected the header \"nm,xbar,ybar,zbar,d65\", found {other:?}"
            ));
        }
    }
    let mut tables = CieTables {
        xyz: [[0.0; CIE_SAMPLES]; 3],
        d65: [0.0; CIE_SAMPLES],
    };
    let mut count = 0;
    for (index, line) in lines {
        let number = index + 1;
        if count == CIE_SAMPLES {
            return Err(format!("line {number}: more than {CIE_SAMPLES} rows"));
        }
        let fields: Vec<f64> = line
            .split(',')
            .map(|field| field.trim().parse::<f64>())
            .collect::<Result<_, _>>()
            .map_err(|e| format!("line {number}: {e}"))?;
        let &[nm, x, y, z, d65] = &fields[..] else {
            return Err(format!(
                "line {number}: expected 5 fields, found {}",
                fields.len()
            ));
        };
        let expected = CIE_MIN + 5.0 * count as f64;
        if nm != expected {
            return Err(format!("line {number}: expected {expected} nm, found {nm}"));
        }
        tables.xyz[0][count] = x as f32;
        tables.xyz[1][count] = y as f32;
        tables.xyz[2][count] = z as f32;
        tables.d65[count] = d65 as f32;
        count += 1;
    }
    if count != CIE_SAMPLES {
        return Err(format!("expected {CIE_SAMPLES} rows, found {count}"));
    }
    Ok(tables)
}

/// Linear interpolation in a 5 nm table, the way Mitsuba's `cie1931_xyz` and `cie_d65` do it:
/// the interval index is clamped so that 830 nm uses the last interval, and the tables end at
/// their range, giving zero outside.
fn lookup(table: &[f32; CIE_SAMPLES], w: f64) -> f64 {
    if !(CIE_MIN..=CIE_MAX).contains(&w) {
        return 0.0;
    }
    let t = (w - CIE_MIN) * ((CIE_SAMPLES - 1) as f64 / (CIE_MAX - CIE_MIN));
    let i0 = (t as usize).min(CIE_SAMPLES - 2);
    let w1 = t - i0 as f64;
    let w0 = 1.0 - w1;
    w0 * f64::from(table[i0]) + w1 * f64::from(table[i0 + 1])
}

/// Parses Mitsuba's `value` list: "400:0.1, 700:0.9" (tokens split on commas and whitespace;
/// each wavelength:value; at least two; strictly increasing wavelengths). Errors are
/// human-readable messages.
///
/// Mitsuba splits on commas and spaces and drops empty tokens, so "400:0.1,,700:0.9" and
/// newlines inside the attribute are accepted as it accepts them. A single number is a uniform
/// spectrum, which is not a list: the caller handles that form before calling this. Unlike
/// Mitsuba, non-finite numbers ("nan", "inf") are refused, since they would only produce a
/// meaningless colour.
pub(crate) fn parse_list(text: &str) -> Result<(Vec<f64>, Vec<f64>), String> {
    let tokens: Vec<&str> = text
        .split(|c: char| c == ',' || c.is_whitespace())
        .filter(|t| !t.is_empty())
        .collect();
    if tokens.is_empty() {
        return Err("empty spectrum value (expected wavelength:value pairs)".to_string());
    }
    if tokens.len() == 1 && !tokens[0].contains(':') {
        return Err(format!(
            "spectrum value \"{}\" is a single number (a uniform spectrum), not a list of \
             wavelength:value pairs",
            tokens[0]
        ));
    }
    let mut wavelengths = Vec::with_capacity(tokens.len());
    let mut values = Vec::with_capacity(tokens.len());
    for token in tokens {
        let parts: Vec<&str> = token.split(':').filter(|p| !p.is_empty()).collect();
        let &[wavelength, value] = &parts[..] else {
            return Err(format!(
                "invalid spectrum value \"{token}\" (expected wavelength:value pairs)"
            ));
        };
        let (Ok(wavelength), Ok(value)) = (wavelength.parse::<f64>(), value.parse::<f64>()) else {
            return Err(format!("could not parse wavelength:value pair \"{token}\""));
        };
        if !wavelength.is_finite() || !value.is_finite() {
            return Err(format!(
                "wavelength:value pair \"{token}\" is not a pair of finite numbers"
            ));
        }
        wavelengths.push(wavelength);
        values.push(value);
    }
    check_list(&wavelengths)?;
    Ok((wavelengths, values))
}

/// The checks Mitsuba makes on any list, from a `value` or from a file.
fn check_list(wavelengths: &[f64]) -> Result<(), String> {
    if wavelengths.len() < 2 {
        return Err(format!(
            "a spectrum needs at least two wavelength:value entries (found {})",
            wavelengths.len()
        ));
    }
    for pair in wavelengths.windows(2) {
        if pair[1] <= pair[0] {
            return Err(format!(
                "wavelengths must be strictly increasing ({} nm is followed by {} nm)",
                pair[0], pair[1]
            ));
        }
    }
    Ok(())
}

/// Reads a .spd file as Mitsuba's XML parser does (lines starting with '#' or empty skipped;
/// two whitespace-separated floats per line, rest ignored; at least two; strictly increasing).
///
/// Mitsuba reads each number like C's `strtod`: leading whitespace is skipped and the number
/// ends where the text stops looking like one, so "550 0.5 nm" is accepted but "550,0.5" is not.
/// A line is skipped only if it is empty or its very first character is '#', so an indented
/// comment or a line of spaces is an error in Mitsuba, and here too. There is no extension
/// check: Mitsuba's XML parser has none.
pub(crate) fn read_spd(path: &Path) -> Result<(Vec<f64>, Vec<f64>), String> {
    let fail = |message: String| {
        format!(
            "failed to load spectrum from file \"{}\": {message}",
            path.display()
        )
    };
    let bytes = std::fs::read(path).map_err(|e| fail(e.to_string()))?;
    let text = String::from_utf8_lossy(&bytes);
    let mut wavelengths = Vec::new();
    let mut values = Vec::new();
    for (index, line) in text.split('\n').enumerate() {
        // A '\r' first is a blank line of a CRLF file.
        if line.is_empty() || line.starts_with('#') || line.starts_with('\r') {
            continue;
        }
        let number = index + 1;
        let shown = line.trim_end_matches('\r');
        let Some((wavelength, rest)) = float_prefix(line) else {
            return Err(fail(format!(
                "could not extract a wavelength in line {number}: \"{shown}\""
            )));
        };
        let Some((value, _)) = float_prefix(rest) else {
            return Err(fail(format!(
                "could not extract a value in line {number}: \"{shown}\""
            )));
        };
        wavelengths.push(wavelength);
        values.push(value);
    }
    check_list(&wavelengths).map_err(fail)?;
    Ok((wavelengths, values))
}

/// Reads a decimal number at the start of `text` after skipping whitespace, like `strtod`, and
/// returns it with the text after it. Only plain decimal forms are read (no "inf", "nan" or hex
/// floats), which keeps non-finite numbers out.
fn float_prefix(text: &str) -> Option<(f64, &str)> {
    let text = text.trim_start_matches(|c: char| c.is_ascii_whitespace() || c == '\x0b');
    let bytes = text.as_bytes();
    let digits = |from: usize| bytes[from..].iter().take_while(|b| b.is_ascii_digit()).count();
    let mut end = 0;
    if matches!(bytes.first(), Some(b'+' | b'-')) {
        end += 1;
    }
    let integer = digits(end);
    end += integer;
    let mut fraction = 0;
    if bytes.get(end) == Some(&b'.') {
        fraction = digits(end + 1);
        if integer + fraction > 0 {
            end += 1 + fraction;
        }
    }
    if integer + fraction == 0 {
        return None;
    }
    if matches!(bytes.get(end), Some(b'e' | b'E')) {
        let mut exponent = end + 1;
        if matches!(bytes.get(exponent), Some(b'+' | b'-')) {
            exponent += 1;
        }
        let exponent_digits = digits(exponent);
        if exponent_digits > 0 {
            end = exponent + exponent_digits;
        }
    }
    let value = text[..end].parse::<f64>().ok().filter(|v| v.is_finite())?;
    Some((value, &text[end..]))
}

/// The linear sRGB colour Mitsuba's RGB variants give the spectrum, for its use (Reflectance:
/// D65-weighted, clamped to [0,1]; Unbounded: D65-weighted, negatives clipped; Emission: no D65
/// weighting, negatives clipped).
///
/// This follows Mitsuba's `spectrum_list_to_srgb` step by step, because its shortcuts change
/// the colour and we want Mitsuba's colour, not an exact integral:
/// - 1000 samples from 360 to 830 nm inclusive (470/999 nm apart), but the sum is scaled by
///   470/1000 nm;
/// - the spectrum is zero outside its first and last wavelengths (Mitsuba's comment says the
///   last value repeats, but its code skips those samples), so a list narrower than 360–830 nm
///   loses light, and one narrower than a sample spacing can be black;
/// - linear interpolation between the listed wavelengths;
/// - out-of-gamut colours are clipped (Mitsuba logs a warning when it does).
///
/// `wavelengths` must be strictly increasing with at least two entries, as [`parse_list`] and
/// [`read_spd`] guarantee.
pub(crate) fn to_rgb(wavelengths: &[f64], values: &[f64], use_: SpectrumUse) -> Rgb {
    debug_assert!(wavelengths.len() >= 2 && wavelengths.len() == values.len());
    let tables = tables();
    let (first, last) = (wavelengths[0], wavelengths[wavelengths.len() - 1]);
    let inner = &wavelengths[1..wavelengths.len() - 1];
    let mut xyz = [0.0f64; 3];
    for i in 0..STEPS {
        let w = CIE_MIN + (i as f64 / (STEPS - 1) as f64) * (CIE_MAX - CIE_MIN);
        if w < first || w > last {
            continue;
        }
        // The last interval k in [0, n-2] with wavelengths[k] <= w (Mitsuba's find_interval).
        let k = inner.partition_point(|&x| x <= w);
        let (w0, w1, v0, v1) = (wavelengths[k], wavelengths[k + 1], values[k], values[k + 1]);
        let v = ((w - w1) * v0 + (w0 - w) * v1) / (w0 - w1);
        let weight = match use_ {
            SpectrumUse::Reflectance | SpectrumUse::Unbounded => lookup(&tables.d65, w) * D65_NORMALIZATION,
            SpectrumUse::Emission => 1.0,
        };
        for (sum, table) in xyz.iter_mut().zip(&tables.xyz) {
            *sum += lookup(table, w) * v * weight;
        }
    }
    let scale = (CIE_MAX - CIE_MIN) * Y_NORMALIZATION / STEPS as f64;
    let xyz = xyz.map(|c| c * scale);
    let rgb = XYZ_TO_SRGB.map(|row| row.iter().zip(&xyz).map(|(&m, &c)| f64::from(m) * c).sum::<f64>());
    let rgb = match use_ {
        SpectrumUse::Reflectance => rgb.map(|c| c.clamp(0.0, 1.0)),
        SpectrumUse::Unbounded | SpectrumUse::Emission => rgb.map(|c| c.max(0.0)),
    };
    Rgb::new(rgb[0] as f32, rgb[1] as f32, rgb[2] as f32)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse_err(text: &str) -> String {
        match parse_list(text) {
            Ok(list) => panic!("{text:?} parsed as {list:?}"),
            Err(message) => message,
        }
    }

    #[test]
    fn parses_lists_as_mitsuba_does() {
        let expected = (vec![400.0, 700.0], vec![0.1, 0.9]);
        for text in [
            "400:0.1, 700:0.9",
            "400:0.1,700:0.9",
            "400:0.1 700:0.9",
            "  400:0.1 ,, 700:0.9  ",
        ] {
            assert_eq!(parse_list(text).unwrap(), expected, "{text:?}");
        }
        assert_eq!(parse_list("400:0.1,\n\t700:0.9").unwrap(), expected);
        assert_eq!(parse_list("4e2:0.1, 7e2:.9").unwrap(), expected);
        assert_eq!(
            parse_list("400:-0.5, 500:2, 700:0").unwrap(),
            (vec![400.0, 500.0, 700.0], vec![-0.5, 2.0, 0.0])
        );
    }

    #[test]
    fn list_errors() {
        assert!(parse_err("").contains("empty"));
        assert!(parse_err(" , ").contains("empty"));
        assert!(parse_err("0.5").contains("uniform"));
        assert!(parse_err("400:0.1").contains("at least two"));
        assert!(parse_err("400:0.1;700:0.9").contains("invalid spectrum value \"400:0.1;700:0.9\""));
        assert!(parse_err("400:0.1, 0.5").contains("invalid spectrum value \"0.5\""));
        assert!(parse_err("400 : 0.1, 700:0.9").contains("invalid spectrum value \"400\""));
        assert!(parse_err("400:0.1:3, 700:1").contains("invalid spectrum value"));
        assert!(parse_err(":1, 700:1").contains("invalid spectrum value"));
        assert!(parse_err("400:, 700:1").contains("invalid spectrum value"));
        assert!(parse_err("400:abc, 700:1").contains("could not parse wavelength:value pair \"400:abc\""));
        assert!(parse_err("400:0.1, 700:0.9x").contains("could not parse"));
        assert!(parse_err("nan:1, 700:1").contains("finite"));
        assert!(parse_err("400:1, inf:1").contains("finite"));
        assert!(parse_err("400:0.1, 400:0.2").contains("strictly increasing"));
        assert!(parse_err("700:0.1, 400:0.2").contains("strictly increasing"));
    }

    fn write_spd(dir: &Path, name: &str, text: &str) -> std::path::PathBuf {
        let path = dir.join(name);
        std::fs::write(&path, text).unwrap();
        path
    }

    #[test]
    fn reads_spd_files_as_mitsuba_does() {
        let (wavelengths, values) = read_spd(&example_spd()).unwrap();
        assert_eq!(wavelengths, [380.0, 450.0, 520.0, 600.0, 680.0, 780.0]);
        assert_eq!(values, [0.05, 0.30, 0.62, 0.48, 0.20, 0.12]);

        let dir = tempfile::tempdir().unwrap();
        let ok = |name: &str, text: &str| read_spd(&write_spd(dir.path(), name, text));
        let expected = (vec![400.0, 700.0], vec![0.1, 0.9]);
        assert_eq!(ok("crlf.spd", "400 0.1\r\n\r\n700 0.9\r\n").unwrap(), expected);
        assert_eq!(
            ok("junk.txt", "  400\t0.1x\n700 0.9 more words").unwrap(),
            expected
        );
        assert_eq!(ok("exp.spd", "4e2 1e-1\n7E+2 .9\n").unwrap(), expected);

        let err = |name: &str, text: &str| ok(name, text).unwrap_err();
        assert!(err("comma.spd", "400,0.1\n700,0.9\n").contains("could not extract a value in line 1"));
        assert!(
            err("ws.spd", "400 0.1\n   \n700 0.9\n").contains("could not extract a wavelength in line 2")
        );
        assert!(err("indented.spd", " # comment\n400 0.1\n700 0.9\n").contains("wavelength in line 1"));
        assert!(err("one.spd", "400 0.1\n700\n").contains("could not extract a value in line 2"));
        assert!(err("single.spd", "# only one\n400 0.1\n").contains("at least two"));
        assert!(err("dec.spd", "700 0.1\n400 0.2\n").contains("strictly increasing"));
        assert!(err("inf.spd", "400 inf\n700 0.2\n").contains("value in line 1"));
        let missing = read_spd(&dir.path().join("missing.spd")).unwrap_err();
        assert!(missing.contains("failed to load spectrum from file"), "{missing}");
    }

    fn example_spd() -> std::path::PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/refs/spectra/example.spd")
    }

    #[test]
    fn cie_tables_are_complete() {
        let tables = tables();
        let at = |nm: usize| (nm - 360) / 5;
        assert_eq!(tables.d65[at(560)], 100.0);
        assert_eq!(tables.xyz[1][at(555)], 1.0);
        // Spot values that Mitsuba's own tests check (test_spectra.py): x̄ and ȳ at 600 nm, and
        // D65 at 456 and 700 nm after normalisation.
        assert!((lookup(&tables.xyz[0], 600.0) - 1.0622).abs() < 1e-6);
        assert!((lookup(&tables.xyz[1], 600.0) - 0.631).abs() < 1e-6);
        assert!((lookup(&tables.d65, 456.0) * D65_NORMALIZATION - 1.186_80).abs() < 1e-5);
        assert!((lookup(&tables.d65, 700.0) * D65_NORMALIZATION - 0.723_34).abs() < 1e-5);
        assert_eq!(lookup(&tables.xyz[1], 359.9), 0.0);
        assert_eq!(lookup(&tables.xyz[1], 830.1), 0.0);
    }

    /// Expected colours for the reflectance, emission and unbounded uses, in that order.
    type Uses = [[f32; 3]; 3];

    /// Colours read from Mitsuba 3.9.1 scalar_rgb (`mi.traverse` of a diffuse `reflectance`, a
    /// point emitter's `intensity` and a conductor's `eta`, each given the spectrum in XML).
    const MITSUBA: &[(&str, Uses)] = &[
        (
            "400:0.1, 700:0.9",
            [
                [0.742_852_8, 0.481_140_08, 0.208_324_55],
                [0.872_214_8, 0.458_728_5, 0.181_301_4],
                [0.742_852_8, 0.481_140_08, 0.208_324_55],
            ],
        ),
        // Extends beyond 360–830 nm.
        (
            "300:0.5, 500:0.2, 900:0.8",
            [
                [0.421_956_2, 0.252_460_42, 0.266_959_73],
                [0.494_927_61, 0.239_860_52, 0.244_906_37],
                [0.421_956_2, 0.252_460_42, 0.266_959_73],
            ],
        ),
        // Narrower than 360–830 nm; blue is negative before clipping.
        (
            "500:0, 550:1, 600:0",
            [
                [0.026_193_209, 0.604_396_7, 0.0],
                [0.044_036_34, 0.582_571_4, 0.0],
                [0.026_193_209, 0.604_396_7, 0.0],
            ],
        ),
        (
            "360:1, 830:1",
            [
                [0.998_985_3, 0.998_873_7, 0.998_801_6],
                [1.204_883_7, 0.948_228_2, 0.909_266_8],
                [0.998_985_3, 0.998_873_7, 0.998_801_6],
            ],
        ),
        // The Cornell box light's radiance: reflectance clips to 1.
        (
            "400:0, 500:8, 600:15.6, 700:18.4",
            [
                [1.0, 1.0, 1.0],
                [20.710_836, 10.854_634, 2.771_152],
                [17.714_712, 11.354_429, 3.304_507_7],
            ],
        ),
        (
            "450:2, 650:2.5",
            [
                [1.0, 1.0, 0.996_666_8],
                [2.541_735, 2.269_989_5, 0.816_528_14],
                [2.114_409_4, 2.374_391_3, 0.996_666_8],
            ],
        ),
        (
            "400:-0.5, 700:0.9",
            [
                [0.628_136_5, 0.167_159_53, 0.0],
                [0.716_582_7, 0.161_848_6, 0.0],
                [0.628_136_5, 0.167_159_53, 0.0],
            ],
        ),
        // Between two of the 1000 sample wavelengths: no sample falls inside, so black.
        ("600.1:3, 600.3:3", [[0.0; 3]; 3]),
    ];

    /// tests/refs/spectra/example.spd, read from Mitsuba 3.9.1 scalar_rgb the same way.
    const MITSUBA_SPD: Uses = [
        [0.367_81, 0.593_239_55, 0.296_960_18],
        [0.455_364_97, 0.565_506_34, 0.261_951],
        [0.367_81, 0.593_239_55, 0.296_960_18],
    ];

    fn assert_close(what: &str, ours: Rgb, mitsuba: [f32; 3]) {
        for (channel, (&a, &b)) in ours.to_array().iter().zip(&mitsuba).enumerate() {
            assert!(
                (a - b).abs() <= 1e-4 * b.abs(),
                "{what}: channel {channel}: ours {ours}, Mitsuba {mitsuba:?}"
            );
        }
    }

    fn check_all_uses(what: &str, wavelengths: &[f64], values: &[f64], expected: Uses) {
        let uses = [
            SpectrumUse::Reflectance,
            SpectrumUse::Emission,
            SpectrumUse::Unbounded,
        ];
        for (use_, mitsuba) in uses.into_iter().zip(expected) {
            assert_close(
                &format!("{what} ({use_:?})"),
                to_rgb(wavelengths, values, use_),
                mitsuba,
            );
        }
    }

    #[test]
    fn matches_mitsuba_for_lists() {
        for &(text, expected) in MITSUBA {
            let (wavelengths, values) = parse_list(text).unwrap();
            check_all_uses(text, &wavelengths, &values, expected);
        }
    }

    #[test]
    fn matches_mitsuba_for_spd_file() {
        let (wavelengths, values) = read_spd(&example_spd()).unwrap();
        check_all_uses("example.spd", &wavelengths, &values, MITSUBA_SPD);
    }
}
