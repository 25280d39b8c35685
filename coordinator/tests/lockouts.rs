//! Lockouts: attacks that used to hold every client off the coordinator or a relay (issue 31,
//! findings 3 to 5), each run against the real service over real sockets, with a legitimate
//! client timed beside the attack: it must be answered within 1 s. Attackers connect from
//! 127.0.0.2 (and 127.0.0.3), legitimate clients from 127.0.0.1: other peers, as on a network.

mod support;

use std::net::SocketAddr;
use std::process::Command;
use std::time::{Duration, Instant};

use photonfarm::film::FilmSum;
use photonfarm::protocol::encode_batch;
use reqwest::StatusCode;
use support::api::*;
use support::{Proc, announced, coordinator_bin};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpSocket, TcpStream};

/// The most a legitimate client may wait under attack.
const SERVED_WITHIN: Duration = Duration::from_secs(1);

fn addr_of(url: &str) -> SocketAddr {
    url.strip_prefix("http://").unwrap().parse().unwrap()
}

/// A connection to `to` from the loopback address `from`, or None if it is not taken within
/// 200 ms (a full listen backlog).
async fn connect_from(from: &str, to: SocketAddr) -> Option<TcpStream> {
    let socket = TcpSocket::new_v4().unwrap();
    socket.bind(format!("{from}:0").parse().unwrap()).unwrap();
    tokio::time::timeout(Duration::from_millis(200), socket.connect(to))
        .await
        .ok()?
        .ok()
}

/// `n` silent connections from `from`.
async fn idle_sockets(from: &str, to: SocketAddr, n: usize) -> Vec<TcpStream> {
    let mut held = Vec::new();
    for _ in 0..n {
        match connect_from(from, to).await {
            Some(s) => held.push(s),
            None => break,
        }
    }
    held
}

/// Keeps opening silent connections from `from` until `stop`, as an attacker that reconnects
/// whenever it is cut off.
fn reconnecting_attacker(
    from: &'static str,
    to: SocketAddr,
    stop: Instant,
) -> tokio::task::JoinHandle<usize> {
    tokio::spawn(async move {
        let mut held = Vec::new();
        while Instant::now() < stop {
            if let Some(s) = connect_from(from, to).await {
                held.push(s);
            }
            tokio::time::sleep(Duration::from_millis(5)).await;
        }
        held.len()
    })
}

/// How long a legitimate client on a new connection from 127.0.0.1 waits for `GET /healthz`.
async fn legitimate_wait(url: &str, token: &str) -> Duration {
    let http = reqwest::Client::builder()
        .pool_max_idle_per_host(0)
        .local_address("127.0.0.1".parse::<std::net::IpAddr>().unwrap())
        .timeout(Duration::from_secs(20))
        .build()
        .unwrap();
    let start = Instant::now();
    let r = http
        .get(format!("{url}/healthz"))
        .bearer_auth(token)
        .send()
        .await
        .expect("the legitimate client is answered");
    assert_eq!(r.status(), StatusCode::OK);
    start.elapsed()
}

/// Under `idle` silent sockets from 127.0.0.2 and an attacker reconnecting from there for
/// `attack`, a legitimate client is answered within [`SERVED_WITHIN`], three times `pause`
/// apart.
async fn served_under_idle_sockets(url: &str, token: &str, idle: usize, attack: Duration, pause: Duration) {
    let to = addr_of(url);
    let _idle = idle_sockets("127.0.0.2", to, idle).await;
    let attacker = reconnecting_attacker("127.0.0.2", to, Instant::now() + attack);
    for _ in 0..3 {
        let waited = legitimate_wait(url, token).await;
        eprintln!("{url}: a legitimate client waited {waited:?}");
        assert!(
            waited < SERVED_WITHIN,
            "waited {waited:?} under {idle} idle sockets"
        );
        tokio::time::sleep(pause).await;
    }
    attacker.await.unwrap();
}

/// Whether the service closes `s` (or answers it) within `within`, writing `keepalive`
/// every 500 ms meanwhile (nothing if empty).
async fn closed_within(s: &mut TcpStream, keepalive: &[u8], within: Duration) -> bool {
    let start = Instant::now();
    let mut buf = [0u8; 256];
    while start.elapsed() < within {
        if !keepalive.is_empty() && s.write_all(keepalive).await.is_err() {
            return true;
        }
        // Closed (0 bytes or an error) or answered: either way the service let go of it.
        if tokio::time::timeout(Duration::from_millis(500), s.read(&mut buf))
            .await
            .is_ok()
        {
            return true;
        }
    }
    false
}

/// Finding 3: 200 idle sockets of one peer, and one reconnecting whenever it is cut off, used
/// to take every connection slot (the cap was global) until the idle timeout; and a socket
/// sending only `\r\n` was never closed. Now a peer holds at most its share, and empty lines
/// are not activity.
#[tokio::test(flavor = "multi_thread")]
async fn idle_sockets_of_one_peer_do_not_lock_others_out() {
    let dir = tempfile::tempdir().unwrap();
    let (_coordinator, url) = serve(
        &dir.path().join("data"),
        "127.0.0.1:0",
        &[
            "--max-connections",
            "64",
            "--max-connections-per-peer",
            "16",
            "--idle-timeout",
            "3",
            "--header-timeout",
            "2",
        ],
    );
    let mut crlf = idle_sockets("127.0.0.3", addr_of(&url), 2).await;
    served_under_idle_sockets(
        &url,
        TOKEN,
        200,
        Duration::from_secs(3),
        Duration::from_millis(800),
    )
    .await;
    // Empty lines every 500 ms: idle, so closed after the 3 s idle timeout.
    for s in &mut crlf {
        assert!(
            closed_within(s, b"\r\n", Duration::from_secs(6)).await,
            "a socket sending only empty lines was never closed"
        );
    }
}

/// Starts a small job and returns nothing; its leases are what the workers below take.
async fn submit_small_job(api: &Api) {
    let (s, v) = api
        .submit(tar_of(&[("s.xml", &scene("", 16, 16))]), r#"{"passes": 200}"#)
        .await;
    assert_eq!(s, StatusCode::CREATED, "{v}");
}

/// A raw request from 127.0.0.2 that sends its head and `sent` bytes of a body of `declared`
/// bytes, then stalls.
async fn stalled_upload(to: SocketAddr, head: String, declared: usize, sent: usize) -> TcpStream {
    let mut s = connect_from("127.0.0.2", to).await.expect("connected");
    let head = format!("{head}Content-Length: {declared}\r\n\r\n");
    s.write_all(head.as_bytes()).await.unwrap();
    s.write_all(&vec![b'-'; sent]).await.unwrap();
    s
}

/// Finding 4: four stalled result bodies (each with a live lease) and two stalled submissions
/// used to hold every upload slot for as long as they were held. Now a result takes a slot only
/// once its body is in, and a body that stalls for --body-timeout is cut off.
#[tokio::test(flavor = "multi_thread")]
async fn stalled_bodies_hold_no_worker_off() {
    let dir = tempfile::tempdir().unwrap();
    let (_coordinator, url) = serve(
        &dir.path().join("data"),
        "127.0.0.1:0",
        &["--max-uploads", "2", "--body-timeout", "2"],
    );
    let api = Api::new(&url);
    let to = addr_of(&url);
    submit_small_job(&api).await;
    let mut stalled = Vec::new();
    for i in 0..4 {
        let lease = api.lease(&format!("stalling-{i}")).await.unwrap();
        let head = format!(
            "PUT /api/leases/{}/result HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer {WORKER_TOKEN}\r\n\
             x-photonfarm-lease-key: {}\r\n",
            lease["lease_id"],
            lease["key"].as_str().unwrap()
        );
        stalled.push(stalled_upload(to, head, 1000, 10).await);
    }
    let form_head = format!(
        "POST /api/jobs HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer {TOKEN}\r\n\
         Content-Type: multipart/form-data; boundary=XyZ\r\n"
    );
    for _ in 0..2 {
        stalled.push(stalled_upload(to, form_head.clone(), 100_000, 0).await);
        let mut s = stalled.pop().unwrap();
        s.write_all(b"--XyZ\r\nContent-Disposition: form-data; name=\"bundle\"; filename=\"b.tar\"\r\n\r\n")
            .await
            .unwrap();
        stalled.push(s);
    }
    tokio::time::sleep(Duration::from_millis(300)).await;

    // An honest worker's result is taken at once.
    let lease = api.lease("honest").await.unwrap();
    let (id, key) = (
        lease["lease_id"].as_u64().unwrap(),
        lease["key"].as_str().unwrap(),
    );
    let mut sum = FilmSum::new(16, 16);
    sum.passes = lease["end"].as_u64().unwrap() - lease["start"].as_u64().unwrap();
    let start = Instant::now();
    let (s, v) = api
        .call(
            reqwest::Method::PUT,
            &format!("/api/leases/{id}/result"),
            WORKER_TOKEN,
            key,
            encode_batch(&sum),
        )
        .await;
    let waited = start.elapsed();
    eprintln!("the honest worker's result waited {waited:?}");
    assert_eq!(s, StatusCode::OK, "{v}");
    assert!(waited < SERVED_WITHIN, "waited {waited:?} behind stalled bodies");

    // The stalled bodies are cut off after the body timeout (2 s), and their slots serve
    // the next submission.
    for s in &mut stalled {
        assert!(
            closed_within(s, b"", Duration::from_secs(6)).await,
            "a stalled body was never cut off"
        );
    }
    let start = Instant::now();
    let (s, v) = api
        .submit(tar_of(&[("s.xml", &scene("", 8, 8))]), r#"{"passes": 2}"#)
        .await;
    assert_eq!(s, StatusCode::CREATED, "{v}");
    assert!(start.elapsed() < Duration::from_secs(3), "{:?}", start.elapsed());
}

fn relay(upstream: &str, extra: &[&str]) -> (Proc, String) {
    // Few descriptors, as on a host with a low limit: the relay used to run out of them.
    let mut command = Command::new("prlimit");
    command
        .arg("--nofile=256:256")
        .arg("--")
        .arg(coordinator_bin())
        .args(["relay", "--upstream", upstream, "--bind", "127.0.0.1:0"])
        .args(["--max-connections", "128"])
        .args(extra)
        .env("PHOTONFARM_TOKEN", WORKER_TOKEN);
    announced(command)
}

/// Finding 5: a relay had none of the coordinator's limits. A 64 MB release body was read
/// whole (a 2.5 GB one aborted it), and 300 idle sockets exhausted its descriptors.
#[tokio::test(flavor = "multi_thread")]
async fn a_relay_holds_the_coordinators_limits() {
    let dir = tempfile::tempdir().unwrap();
    let (_coordinator, url) = serve(&dir.path().join("data"), "127.0.0.1:0", &[]);
    let (mut relay, relay_url) = relay(&url, &["--idle-timeout", "3", "--header-timeout", "2"]);
    // Declared, and only its first 128 KiB sent: a client writing 64 MB while the relay has
    // already answered can see its write fail first. The relay must answer once its 64 KiB
    // JSON limit is passed (it used to read on to the declared end).
    let start = Instant::now();
    let mut s = connect_from("127.0.0.1", addr_of(&relay_url))
        .await
        .expect("connected");
    let head = format!(
        "POST /api/leases/1/release HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer {WORKER_TOKEN}\r\n\
         x-photonfarm-lease-key: k\r\nContent-Type: application/json\r\nContent-Length: {}\r\n\r\n{{\"error\": ",
        64 << 20
    );
    s.write_all(head.as_bytes()).await.unwrap();
    s.write_all(&vec![b' '; 128 << 10]).await.unwrap();
    let mut answer = vec![0u8; 64];
    let n = tokio::time::timeout(Duration::from_secs(5), s.read(&mut answer))
        .await
        .expect("answered past the limit, before the declared end")
        .unwrap();
    let answer = String::from_utf8_lossy(&answer[..n]).to_string();
    assert!(answer.starts_with("HTTP/1.1 413"), "{answer}");
    eprintln!("a 64 MB release body was refused in {:?}", start.elapsed());

    served_under_idle_sockets(
        &relay_url,
        WORKER_TOKEN,
        300,
        Duration::from_secs(2),
        Duration::from_millis(700),
    )
    .await;
    assert!(relay.0.try_wait().unwrap().is_none(), "the relay died");
}
