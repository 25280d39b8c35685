//! The worker's command line as a user meets it. (Also makes `cargo test` build the worker
//! binary that the farm tests in coordinator/tests start.)

use std::process::Command;

#[test]
fn bad_arguments_fail_with_a_message() {
    let worker = env!("CARGO_BIN_EXE_worker");
    let o = Command::new(worker).output().unwrap();
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("--coordinator"));
    let o = Command::new(worker)
        .args(["--coordinator", "http://127.0.0.1:9", "--threads", "0"])
        .output()
        .unwrap();
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("--threads must be at least 1"));
}

/// A worker says what is wrong: a URL without a scheme at once, an unreachable coordinator
/// within two seconds (naming the address and the reason), and a refused token by exiting.
#[test]
fn a_worker_says_what_is_wrong() {
    let worker = env!("CARGO_BIN_EXE_worker");
    let o = Command::new(worker)
        .args(["--coordinator", "127.0.0.1:9", "--threads", "1"])
        .output()
        .unwrap();
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("http://"), "{err}");

    // A dead port: the error is logged at once; the worker keeps trying (the coordinator may
    // be restarting), so it is stopped here.
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let url = format!("http://127.0.0.1:{port}");
    let mut child = Command::new(worker)
        .args(["--coordinator", &url, "--threads", "1"])
        .env("RUST_LOG", "info")
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_secs(2));
    child.kill().unwrap();
    let o = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("cannot reach the coordinator") && err.contains(&url),
        "{err}"
    );

    // A token the coordinator refuses: five refusals in a row end the worker with exit code 3.
    let (url, _bodies) = refusing_coordinator();
    let mut child = Command::new(worker)
        .args(["--coordinator", &url, "--threads", "1", "--token", "wrong"])
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // Bounded: a worker that never gives up is killed and the test fails.
    let start = std::time::Instant::now();
    while child.try_wait().unwrap().is_none() && start.elapsed() < std::time::Duration::from_secs(30) {
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    let _ = child.kill();
    let o = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(3), "{err}");
    assert!(err.contains("refused this worker's token"), "{err}");
}

/// A worker named by nobody is named after its host and its process id, as `--help` says.
#[test]
fn the_default_name_is_the_host_name_and_the_process_id() {
    let (url, bodies) = refusing_coordinator();
    let mut child = Command::new(env!("CARGO_BIN_EXE_worker"))
        .args(["--coordinator", &url, "--threads", "1", "--token", "wrong"])
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let pid = child.id();
    let body = bodies
        .recv_timeout(std::time::Duration::from_secs(30))
        .expect("the worker asked for work");
    let _ = child.kill();
    let _ = child.wait();
    let host = gethostname::gethostname().to_string_lossy().into_owned();
    let request: serde_json::Value = serde_json::from_slice(&body).unwrap();
    assert_eq!(request["worker"], format!("{host}-{pid}"), "{request}");
}

/// A coordinator that refuses every request with 401; the request bodies come out of the
/// channel.
fn refusing_coordinator() -> (String, std::sync::mpsc::Receiver<Vec<u8>>) {
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let url = format!("http://{}", listener.local_addr().unwrap());
    let (send, receive) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        use std::io::{BufRead, BufReader, Read, Write};
        for stream in listener.incoming().flatten() {
            // Read the whole request (head and body), then refuse it.
            let mut reader = BufReader::new(stream);
            let mut length = 0usize;
            loop {
                let mut line = String::new();
                if reader.read_line(&mut line).unwrap_or(0) == 0 || line == "\r\n" {
                    break;
                }
                if let Some(v) = line.to_ascii_lowercase().strip_prefix("content-length:") {
                    length = v.trim().parse().unwrap_or(0);
                }
            }
            let mut body = vec![0u8; length];
            let _ = reader.read_exact(&mut body);
            let _ = send.send(body);
            let _ = reader
                .get_mut()
                .write_all(b"HTTP/1.1 401 Unauthorized\r\ncontent-length: 0\r\nconnection: close\r\n\r\n");
        }
    });
    (url, receive)
}
