//! Time-bounded mutation fuzzing of the three parsers that read untrusted bytes: the scene
//! loader (XML from users), the bundle unpacker (tar archives from users) and the batch
//! decoder (results from workers).
//!
//! Each target starts from valid inputs (the repository's scenes, a packed bundle, an encoded
//! result), mutates them with a seeded generator (bit flips, interesting bytes, insertions,
//! deletions, duplications, splices) and checks that the parser returns, never panics, and
//! keeps its promises (an unpacked bundle stays in its folder; a decoded result is whole and
//! survives a round trip). CI runs each target for `PHOTONFARM_FUZZ_SECONDS` (default 3) seconds; a
//! longer run is the same command with a larger value, and `PHOTONFARM_FUZZ_SEED` picks
//! another sequence. A failing input is written to the temporary folder and named in the
//! panic message, so it can be replayed.

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use photonfarm::bundle::{UnpackLimits, pack, unpack};
use photonfarm::film::FilmSum;
use photonfarm::protocol::{decode_batch, encode_batch};
use photonfarm::scene::Scene;
use rand_core::Rng;
use rand_pcg::Pcg32;

fn budget() -> Duration {
    let s = std::env::var("PHOTONFARM_FUZZ_SECONDS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(3.0);
    Duration::from_secs_f64(s)
}

fn rng(target: u64) -> Pcg32 {
    let seed: u64 = std::env::var("PHOTONFARM_FUZZ_SEED")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(11);
    Pcg32::new(seed, target * 2 + 1)
}

const INTERESTING: &[u8] = b"\x00\xff\x7f\x80<>/\"=$-.0123456789 eE\n";

/// One random mutation of `input`, possibly splicing from `other`.
fn mutate(r: &mut Pcg32, input: &mut Vec<u8>, other: &[u8]) {
    let mut pick = |n: usize| (r.next_u64() % n.max(1) as u64) as usize;
    let len = input.len();
    match pick(7) {
        0 if len > 0 => {
            let i = pick(len);
            input[i] ^= 1 << pick(8);
        }
        1 if len > 0 => {
            let i = pick(len);
            input[i] = INTERESTING[pick(INTERESTING.len())];
        }
        2 => {
            let i = pick(len + 1);
            let n = 1 + pick(8);
            for _ in 0..n {
                input.insert(i, INTERESTING[pick(INTERESTING.len())]);
            }
        }
        3 if len > 1 => {
            let i = pick(len);
            let n = 1 + pick((len - i).min(64));
            input.drain(i..(i + n).min(len));
        }
        4 if len > 1 => {
            // Duplicate a slice (repeats elements, attributes, numbers).
            let i = pick(len);
            let n = 1 + pick((len - i).min(256));
            let chunk = input[i..(i + n).min(len)].to_vec();
            let at = pick(len + 1);
            input.splice(at..at, chunk);
        }
        5 if !other.is_empty() => {
            let i = pick(other.len());
            let n = 1 + pick((other.len() - i).min(256));
            let at = pick(len + 1);
            input.splice(at..at, other[i..(i + n).min(other.len())].iter().copied());
        }
        _ if len > 0 => {
            // Overwrite a little-endian word with an extreme value (lengths, sizes).
            let i = pick(len);
            let v = [0u64, 1, u32::MAX as u64, u64::MAX, 1 << 31, 65536][pick(6)].to_le_bytes();
            for (k, b) in v.iter().enumerate().take(len - i) {
                input[i + k] = *b;
            }
        }
        _ => input.push(INTERESTING[pick(INTERESTING.len())]),
    }
}

/// Runs `check` on mutants of `seeds` until the time budget is spent; returns the count.
fn fuzz(name: &str, target: u64, seeds: &[Vec<u8>], mut check: impl FnMut(&[u8])) -> usize {
    let mut r = rng(target);
    let deadline = Instant::now() + budget();
    let mut runs = 0;
    while Instant::now() < deadline {
        let a = (r.next_u64() % seeds.len() as u64) as usize;
        let b = (r.next_u64() % seeds.len() as u64) as usize;
        let mut input = seeds[a].clone();
        for _ in 0..1 + r.next_u64() % 4 {
            mutate(&mut r, &mut input, &seeds[b]);
        }
        if catch_unwind(AssertUnwindSafe(|| check(&input))).is_err() {
            let path = std::env::temp_dir().join(format!("photonfarm-fuzz-{name}-{runs}.bin"));
            std::fs::write(&path, &input).unwrap();
            panic!("{name}: input {} makes the parser panic", path.display());
        }
        runs += 1;
    }
    eprintln!("{name}: {runs} inputs in {:?}", budget());
    runs
}

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn scene_seeds() -> Vec<Vec<u8>> {
    let mut seeds = Vec::new();
    for dir in ["scenes", "tests/refs", "tests/scenes"] {
        let Ok(entries) = std::fs::read_dir(repo().join(dir)) else {
            continue;
        };
        for e in entries.flatten() {
            if e.path().extension().is_some_and(|x| x == "xml") {
                seeds.push(std::fs::read(e.path()).unwrap());
            }
        }
    }
    assert!(seeds.len() >= 5, "the repository's scenes are the seeds");
    seeds
}

#[test]
fn scene_loader_never_panics() {
    let seeds = scene_seeds();
    // Scenes load meshes relative to their path: a folder with none, so only XML is fuzzed.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("fuzz.xml");
    let runs = fuzz("scene", 1, &seeds, |input| {
        let text = String::from_utf8_lossy(input);
        let _ = Scene::from_str(&text, &path, &[("res".into(), "8".into())]);
    });
    assert!(runs > 0);
}

#[test]
fn bundle_unpacker_never_panics_or_escapes() {
    let src = tempfile::tempdir().unwrap();
    std::fs::create_dir(src.path().join("meshes")).unwrap();
    std::fs::write(src.path().join("scene.xml"), scene_seeds()[0].clone()).unwrap();
    std::fs::write(
        src.path().join("meshes/a.obj"),
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
    )
    .unwrap();
    let seeds = vec![
        pack(&src.path().join("scene.xml"), &[src.path().join("meshes/a.obj")])
            .unwrap()
            .0,
    ];
    let root = tempfile::tempdir().unwrap();
    let limits = UnpackLimits {
        max_files: 100,
        max_bytes: 1 << 20,
    };
    let mut n = 0u64;
    let runs = fuzz("bundle", 2, &seeds, |input| {
        n += 1;
        let dest = root.path().join(format!("b{n}"));
        if let Ok(files) = unpack(input, &dest, &limits) {
            for f in files {
                let real = dest.join(&f).canonicalize().unwrap();
                assert!(real.starts_with(dest.canonicalize().unwrap()), "{f:?} escaped");
            }
        }
        let _ = std::fs::remove_dir_all(&dest);
    });
    // Nothing was written beside the destinations.
    let stray: Vec<_> = std::fs::read_dir(root.path()).unwrap().flatten().collect();
    assert!(stray.is_empty(), "{stray:?}");
    assert!(runs > 0);
}

#[test]
fn batch_decoder_never_panics_and_round_trips() {
    let mut seeds = Vec::new();
    for (w, h) in [(1, 1), (3, 2), (16, 16)] {
        let mut f = FilmSum::new(w, h);
        for (i, s) in f.sums.iter_mut().enumerate() {
            *s = [i as i64, -(i as i64) * 1000, i64::MAX - i as i64];
        }
        f.passes = 5;
        f.nonfinite = 2;
        seeds.push(encode_batch(&f));
    }
    let runs = fuzz("batch", 3, &seeds, |input| {
        for (w, h) in [(1, 1), (3, 2), (16, 16)] {
            if let Ok(sum) = decode_batch(input, w, h) {
                assert_eq!((sum.width, sum.height, sum.sums.len()), (w, h, (w * h) as usize));
                assert_eq!(decode_batch(&encode_batch(&sum), w, h).unwrap(), sum);
            }
        }
    });
    assert!(runs > 0);
}
