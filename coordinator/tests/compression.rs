//! Results compressed on the wire, against a real `coordinator serve`: leases offer zstd,
//! zstd and plain results (older workers) are both accepted, an unknown encoding is refused
//! with 415, and a zip bomb gets 413 without being expanded (the lease stays usable).

mod support;

use photonfarm::film::FilmSum;
use photonfarm::parity::OddSums;
use photonfarm::protocol::encode_result;
use reqwest::StatusCode;
use support::api::*;

fn result_8x8() -> Vec<u8> {
    let mut sum = FilmSum::new(8, 8);
    sum.passes = 1;
    sum.sums
        .iter_mut()
        .enumerate()
        .for_each(|(i, s)| *s = [i as i64 * 1000, 7, 1 << 30]);
    encode_result(&sum, &OddSums::empty(8, 8), None)
}

async fn put(api: &Api, id: u64, key: &str, encoding: Option<&str>, body: Vec<u8>) -> StatusCode {
    let mut r = api
        .http
        .put(format!("{}/api/leases/{id}/result", api.url))
        .bearer_auth(WORKER_TOKEN)
        .header("x-photonfarm-lease-key", key);
    if let Some(e) = encoding {
        r = r.header("content-encoding", e);
    }
    r.body(body).send().await.unwrap().status()
}

#[tokio::test]
async fn compressed_and_plain_results_are_accepted_and_bombs_refused() {
    let dir = tempfile::tempdir().unwrap();
    let (_serve, url) = serve(dir.path(), "127.0.0.1:0", &[]);
    let api = Api::new(&url);
    let (s, job) = api
        .submit(tar_of(&[("s.xml", &scene("", 8, 8))]), r#"{"passes": 2}"#)
        .await;
    assert_eq!(s, StatusCode::CREATED, "{job}");

    let lease = api.lease("w").await.unwrap();
    assert_eq!(lease["accept_encoding"], serde_json::json!(["zstd"]), "{lease}");
    assert_eq!(
        (lease["width"].as_u64(), lease["height"].as_u64()),
        (Some(8), Some(8))
    );
    let (id, key) = (
        lease["lease_id"].as_u64().unwrap(),
        lease["key"].as_str().unwrap().to_string(),
    );
    // 64 MB of zeros in a few kilobytes: refused while expanding, past the 8×8 limit (5 KB).
    let bomb = zstd::bulk::compress(&vec![0u8; 64 << 20], 19).unwrap();
    assert!(bomb.len() < 64 << 10);
    assert_eq!(
        put(&api, id, &key, Some("zstd"), bomb).await,
        StatusCode::PAYLOAD_TOO_LARGE
    );
    assert_eq!(
        put(&api, id, &key, Some("gzip"), result_8x8()).await,
        StatusCode::UNSUPPORTED_MEDIA_TYPE
    );
    let z = photonfarm::compression::compress(&result_8x8());
    assert_eq!(put(&api, id, &key, Some("zstd"), z).await, StatusCode::OK);

    // A worker from before compression sends plain bytes: still accepted.
    let lease = api.lease("old").await.unwrap();
    let (id, key) = (
        lease["lease_id"].as_u64().unwrap(),
        lease["key"].as_str().unwrap().to_string(),
    );
    assert_eq!(lease["start"], 1);
    let mut plain = result_8x8();
    // Pass 1 is odd: its sample must hold one odd pass; a one-pass PFBATCH1 needs none.
    plain = {
        let r = photonfarm::protocol::decode_result(&plain, 8, 8).unwrap();
        photonfarm::protocol::encode_batch(&r.sum)
    };
    assert_eq!(put(&api, id, &key, None, plain).await, StatusCode::OK);
    let (_, status) = api.get(&format!("/api/jobs/{}", job["id"])).await;
    assert_eq!(status["iterations_done"], 2, "{status}");
}

/// Issue 31's finding 1, as the probe ran it: four 2048² results of a few kilobytes of zstd,
/// each claiming 56 M pixels in 150 MB of zeros (3 bytes per zero pixel in bincode's varints,
/// within what a 2048² result may expand to), sent at once to a coordinator whose address
/// space is capped at 2 GiB. Decoded without a bound, each became about 1.3 GB of pixel sums
/// and the coordinator aborted. Each is now refused at the vector's length, and the service
/// goes on.
#[tokio::test(flavor = "multi_thread")]
async fn decode_bombs_leave_a_memory_capped_coordinator_up() {
    let dir = tempfile::tempdir().unwrap();
    let (mut serve, url) = support::serve_limited(
        &dir.path().join("data"),
        "127.0.0.1:0",
        &[],
        &[
            ("PHOTONFARM_TOKEN", TOKEN),
            ("PHOTONFARM_WORKER_TOKEN", WORKER_TOKEN),
        ],
        Some(2048),
    );
    let api = Api::new(&url);
    let (s, job) = api
        .submit(tar_of(&[("s.xml", &scene("", 2048, 2048))]), r#"{"passes": 100}"#)
        .await;
    assert_eq!(s, StatusCode::CREATED, "{job}");
    // PFBATCH1, then bincode's varints: width and height 2048 (251 + u16), and a pixel vector
    // of 56,000,000 (252 + u32), then zeros.
    let mut plain = b"PFBATCH1".to_vec();
    plain.extend([251, 0, 8, 251, 0, 8, 252]);
    plain.extend(56_000_000u32.to_le_bytes());
    plain.resize(plain.len() + 150_000_000, 0);
    let bomb = zstd::bulk::compress(&plain, 3).unwrap();
    drop(plain);
    eprintln!("each bomb is {} bytes", bomb.len());
    assert!(bomb.len() < 64 << 10);
    let mut uploads = Vec::new();
    for i in 0..4 {
        let lease = api.lease(&format!("bomber-{i}")).await.unwrap();
        let (id, key) = (
            lease["lease_id"].as_u64().unwrap(),
            lease["key"].as_str().unwrap().to_string(),
        );
        let (api, bomb) = (Api::new(&url), bomb.clone());
        uploads.push(tokio::spawn(async move {
            put(&api, id, &key, Some("zstd"), bomb).await
        }));
    }
    for u in uploads {
        assert_eq!(u.await.unwrap(), StatusCode::BAD_REQUEST);
    }
    assert!(serve.0.try_wait().unwrap().is_none(), "the coordinator died");
    let (s, status) = api.get(&format!("/api/jobs/{}", job["id"])).await;
    assert_eq!(s, StatusCode::OK, "{status}");
}
