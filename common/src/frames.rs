//! Frame sequences: which frames (Flamenco's frame lists), what each frame sets (the `frame`
//! parameter and `-D name=A:B` ramps), where each goes (Blender's `####` names) and its seed.
//!
//! One definition for every renderer of a sequence, so that a frame rendered alone, in a local
//! sequence or on the farm gets the same parameters and seed, and so the same bytes.

use std::path::{Path, PathBuf};

/// The scene parameter each frame sets to its number (Mitsuba's `$frame`). A scene need not use
/// it: unlike a `-D` parameter, it is no error when no `$frame` reads it.
pub const FRAME_PARAMETER: &str = "frame";

/// The most frames one sequence may have (each is a render and a file).
pub const MAX_FRAMES: u64 = 100_000;

/// Why a frame list, a ramp or an output name cannot be used.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum FrameError {
    /// The frame list does not parse.
    #[error("frames \"{spec}\": {why}")]
    List {
        /// The list as given.
        spec: String,
        /// What is wrong.
        why: String,
    },
    /// A `-D name=A:B` ramp whose ends are not numbers.
    #[error("-D {name}={value}: a ramp over the frames is FIRST:LAST, two numbers")]
    Ramp {
        /// The parameter.
        name: String,
        /// Its value.
        value: String,
    },
}

/// Parses a frame list in Flamenco's syntax: comma-separated frames (`150`), ranges (`1-240`)
/// and ranges with a step (`1-100x2`, every other frame). Frames keep the order given; one
/// listed twice is refused, since both would write the same file.
pub fn parse_frames(spec: &str) -> Result<Vec<u32>, FrameError> {
    let fail = |why: String| FrameError::List {
        spec: spec.to_string(),
        why,
    };
    let number = |s: &str| {
        s.trim().parse::<u32>().map_err(|_| {
            fail(format!(
                "\"{}\" is not a frame number (a whole number from 0)",
                s.trim()
            ))
        })
    };
    let mut items = Vec::new();
    let mut count = 0u64;
    for item in spec.split(',') {
        let item = item.trim();
        if item.is_empty() {
            return Err(fail("an empty item (write 1-10,20, not 1-10,,20)".into()));
        }
        let (range, step) = match item.split_once('x') {
            Some((r, s)) => (r, number(s)?),
            None => (item, 1),
        };
        if step == 0 {
            return Err(fail(format!("{item}: the step must be at least 1")));
        }
        let (first, last) = match range.split_once('-') {
            Some((a, b)) => (number(a)?, number(b)?),
            None if step == 1 => (number(range)?, number(range)?),
            None => return Err(fail(format!("{item}: a step needs a range (1-100x2)"))),
        };
        if first > last {
            return Err(fail(format!("{item}: the range runs backwards")));
        }
        count += (last - first) as u64 / step as u64 + 1;
        if count > MAX_FRAMES {
            return Err(fail(format!("more than {MAX_FRAMES} frames")));
        }
        items.push((first, last, step));
    }
    let mut frames = Vec::with_capacity(count as usize);
    let mut seen = std::collections::HashSet::new();
    for (first, last, step) in items {
        for f in (first..=last).step_by(step as usize) {
            if !seen.insert(f) {
                return Err(fail(format!("frame {f} is listed twice")));
            }
            frames.push(f);
        }
    }
    Ok(frames)
}

/// The parameters of `frame` of the sequence `frames`: each `-D name=A:B` becomes its value
/// interpolated linearly from A at the first frame to B at the last (by frame number), others
/// stay as given, and [`FRAME_PARAMETER`] is the frame's number unless `-D` sets it.
pub fn frame_defines(
    defines: &[(String, String)],
    frames: &[u32],
    frame: u32,
) -> Result<Vec<(String, String)>, FrameError> {
    let first = frames.iter().copied().min().unwrap_or(frame);
    let last = frames.iter().copied().max().unwrap_or(frame);
    let t = if last > first {
        (frame - first) as f64 / (last - first) as f64
    } else {
        0.0
    };
    let mut out = Vec::with_capacity(defines.len() + 1);
    for (name, value) in defines {
        let value = match ramp(value) {
            Ramp::Constant => value.clone(),
            Ramp::Between(a, b) => format_number(a + (b - a) * t),
            Ramp::Bad => {
                return Err(FrameError::Ramp {
                    name: name.clone(),
                    value: value.clone(),
                });
            }
        };
        out.push((name.clone(), value));
    }
    if !defines.iter().any(|(n, _)| n == FRAME_PARAMETER) {
        out.push((FRAME_PARAMETER.to_string(), frame.to_string()));
    }
    Ok(out)
}

enum Ramp {
    Constant,
    Between(f64, f64),
    Bad,
}

/// `A:B` with two numbers is a ramp; a value with a colon whose sides are not both numbers is
/// refused rather than passed on (a typo in a ramp must not render a still sequence).
fn ramp(value: &str) -> Ramp {
    let Some((a, b)) = value.split_once(':') else {
        return Ramp::Constant;
    };
    match (a.trim().parse::<f64>(), b.trim().parse::<f64>()) {
        (Ok(a), Ok(b)) if a.is_finite() && b.is_finite() => Ramp::Between(a, b),
        _ => Ramp::Bad,
    }
}

/// The shortest decimal that reads back as `x` (Rust's formatting: the same on every machine).
fn format_number(x: f64) -> String {
    let x = if x == 0.0 { 0.0 } else { x };
    format!("{x}")
}

/// The output of `frame`: each run of `#` in the file name becomes the frame number padded with
/// zeros to the run's length (`shots/cbox-####.exr` → `shots/cbox-0007.exr`); a name without
/// `#` gets the number, four digits, before its extension, as Blender appends it.
pub fn frame_path(out: &Path, frame: u32) -> PathBuf {
    let name = out
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    if !name.contains('#') {
        return crate::film::beside(out, &format!("{frame:04}"));
    }
    let name = {
        let mut s = String::with_capacity(name.len() + 8);
        let mut chars = name.chars().peekable();
        while let Some(c) = chars.next() {
            if c == '#' {
                let mut width = 1;
                while chars.peek() == Some(&'#') {
                    chars.next();
                    width += 1;
                }
                s.push_str(&format!("{frame:0width$}"));
            } else {
                s.push(c);
            }
        }
        s
    };
    out.with_file_name(name)
}

/// The seed of `frame` in a sequence rendered with `seed`: each frame its own random numbers
/// (the noise of a still sequence must not stand still), the same on every machine.
pub fn frame_seed(seed: u64, frame: u32) -> u64 {
    crate::sampling::mix64(seed ^ crate::sampling::mix64(0x6672_616d_6500_0000 | frame as u64))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flamenco_frame_lists() {
        assert_eq!(parse_frames("1-6").unwrap(), vec![1, 2, 3, 4, 5, 6]);
        assert_eq!(parse_frames("150").unwrap(), vec![150]);
        assert_eq!(parse_frames("1-9x4, 150").unwrap(), vec![1, 5, 9, 150]);
        assert_eq!(parse_frames("0-3x2,10-11").unwrap(), vec![0, 2, 10, 11]);
        for (bad, why) in [
            ("", "empty item"),
            ("1-", "not a frame number"),
            ("-3", "not a frame number"),
            ("5-1", "backwards"),
            ("1-10x0", "at least 1"),
            ("4x2", "needs a range"),
            ("1-4,3", "frame 3 is listed twice"),
            ("0-4294967295", "more than 100000 frames"),
            ("1.5", "not a frame number"),
        ] {
            let e = parse_frames(bad).unwrap_err().to_string();
            assert!(e.contains(why), "{bad}: {e}");
        }
    }

    #[test]
    fn ramps_run_from_the_first_frame_to_the_last() {
        let defines = vec![
            ("angle".to_string(), "0:90".to_string()),
            ("spp".to_string(), "16".to_string()),
        ];
        let frames = parse_frames("1-3,5").unwrap();
        let at = |f| frame_defines(&defines, &frames, f).unwrap();
        assert_eq!(at(1)[0].1, "0");
        assert_eq!(at(3)[0].1, "45");
        assert_eq!(at(5)[0].1, "90");
        assert_eq!(at(2)[1], ("spp".to_string(), "16".to_string()));
        assert_eq!(at(2)[2], ("frame".to_string(), "2".to_string()));
        // One frame: the ramp's start. A frame set by -D stays as set.
        let one = frame_defines(&defines, &[7], 7).unwrap();
        assert_eq!(one[0].1, "0");
        let fixed = vec![("frame".to_string(), "12".to_string())];
        assert_eq!(frame_defines(&fixed, &frames, 2).unwrap(), fixed);
        let bad = vec![("camx".to_string(), "1:two".to_string())];
        assert!(matches!(
            frame_defines(&bad, &frames, 1),
            Err(FrameError::Ramp { .. })
        ));
    }

    #[test]
    fn outputs_follow_blender_padding() {
        let p = |s: &str, f| frame_path(Path::new(s), f).to_string_lossy().into_owned();
        assert_eq!(p("shots/cbox-####.exr", 7), "shots/cbox-0007.exr");
        assert_eq!(p("shots/cbox-##.png", 123), "shots/cbox-123.png");
        assert_eq!(p("a#b###.exr", 5), "a5b005.exr");
        assert_eq!(p("shots/cbox.exr", 7), "shots/cbox0007.exr");
        // Only the file name is rewritten.
        assert_eq!(p("take#2/cbox-#.exr", 3), "take#2/cbox-3.exr");
    }

    #[test]
    fn each_frame_has_its_own_seed() {
        let seeds: std::collections::HashSet<u64> = (0..1000).map(|f| frame_seed(0, f)).collect();
        assert_eq!(seeds.len(), 1000);
        assert_ne!(frame_seed(0, 1), frame_seed(1, 1));
        assert_eq!(frame_seed(3, 9), frame_seed(3, 9));
    }
}
