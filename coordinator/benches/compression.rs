//! Results on the wire: `cargo bench -p coordinator --bench compression`.
//!
//! Makes realistic results (the sums of `n` passes of a real 512² and 1920×1080 render of
//! cbox-spheres, with their noise: see `coordinator::client::synthetic`) and prints, on one core, the
//! size of the `PFBATCH2` encoding, and for zstd (levels 1 and 3) and lz4 (lz4_flex, frame
//! format) the compression ratio and MB/s compressing and decompressing (of uncompressed
//! bytes), then what else a result costs the coordinator: decoding and adding it.
//! Medians of 5 runs.

use std::time::Instant;

use coordinator::client::synthetic::Synthetic;
use photonfarm::protocol::decode_result;

fn median(mut f: impl FnMut() -> f64) -> f64 {
    let mut v: Vec<f64> = (0..5).map(|_| f()).collect();
    v.sort_by(f64::total_cmp);
    v[2]
}

fn timed(f: impl FnOnce()) -> f64 {
    let t = Instant::now();
    f();
    t.elapsed().as_secs_f64()
}

fn main() {
    rayon::ThreadPoolBuilder::new().num_threads(1).build_global().ok();
    for (w, h) in [(512u32, 512u32), (1920, 1080)] {
        let dir = std::env::temp_dir().join(format!("pf-compression-bench-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("scene.xml");
        std::fs::write(&path, coordinator::client::loadgen::scene_xml(w, h)).unwrap();
        let scene = photonfarm::scene::Scene::load(&path, &[]).unwrap();
        let _ = std::fs::remove_dir_all(&dir);
        let synthetic = Synthetic::render(&scene);
        for passes in [1u64, 16] {
            let plain = synthetic.encoded(passes, passes / 2, 3);
            let mb = plain.len() as f64 / 1e6;
            println!(
                "{w}x{h}, {passes} passes: PFBATCH2 {:.2} MB ({:.2} B/pixel)",
                mb,
                plain.len() as f64 / (w * h) as f64
            );
            for level in [1, 3] {
                let z = zstd::bulk::compress(&plain, level).unwrap();
                let c = median(|| timed(|| drop(zstd::bulk::compress(&plain, level).unwrap())));
                let d = median(|| timed(|| drop(zstd::bulk::decompress(&z, plain.len()).unwrap())));
                println!(
                    "  zstd -{level}: ratio {:.2} ({:.2} MB), compress {:.0} MB/s, decompress {:.0} MB/s",
                    plain.len() as f64 / z.len() as f64,
                    z.len() as f64 / 1e6,
                    mb / c,
                    mb / d
                );
            }
            let lz = {
                let mut e = lz4_flex::frame::FrameEncoder::new(Vec::new());
                std::io::Write::write_all(&mut e, &plain).unwrap();
                e.finish().unwrap()
            };
            let c = median(|| {
                timed(|| {
                    let mut e = lz4_flex::frame::FrameEncoder::new(Vec::new());
                    std::io::Write::write_all(&mut e, &plain).unwrap();
                    drop(e.finish().unwrap());
                })
            });
            let d = median(|| {
                timed(|| {
                    let mut out = Vec::new();
                    std::io::Read::read_to_end(&mut lz4_flex::frame::FrameDecoder::new(&lz[..]), &mut out)
                        .unwrap();
                })
            });
            println!(
                "  lz4 (frame): ratio {:.2} ({:.2} MB), compress {:.0} MB/s, decompress {:.0} MB/s",
                plain.len() as f64 / lz.len() as f64,
                lz.len() as f64 / 1e6,
                mb / c,
                mb / d
            );
            let dec = median(|| timed(|| drop(decode_result(&plain, w, h).unwrap())));
            let r = decode_result(&plain, w, h).unwrap();
            let mut acc = r.sum.clone();
            let add = median(|| timed(|| acc.add(&r.sum).unwrap()));
            println!(
                "  decode (bincode) {:.1} ms, add to a sum {:.1} ms",
                dec * 1e3,
                add * 1e3
            );
        }
    }
}
