//! Bad input against a running coordinator: each request gets the right 4xx with a JSON error,
//! and the service keeps serving.

mod support;

use support::api::tar_of;

use std::path::{Path, PathBuf};

use reqwest::StatusCode;
use reqwest::multipart::{Form, Part};
use serde_json::Value;

const TOKEN: &str = "s3cret-token";

fn serve(data: &Path) -> (support::Proc, String) {
    support::serve(
        data,
        "127.0.0.1:0",
        &["--max-upload-mb", "1"],
        &[("PHOTONFARM_TOKEN", TOKEN)],
    )
}

fn refs() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/refs")
}

/// A tar whose single entry is named `name` verbatim (the tar crate refuses to write "..").
fn raw_tar_entry(name: &str) -> Vec<u8> {
    let mut header = tar::Header::new_old();
    header.as_old_mut().name[..name.len()].copy_from_slice(name.as_bytes());
    header.set_size(1);
    header.set_mode(0o644);
    header.set_entry_type(tar::EntryType::Regular);
    header.set_cksum();
    let mut bytes = header.as_bytes().to_vec();
    bytes.push(b'x');
    bytes.resize(bytes.len() + 511, 0);
    bytes.extend_from_slice(&[0; 1024]);
    bytes
}

/// A POST over a raw socket: the body is written from another thread while the response is
/// read, so a server that answers early (401, 413) and closes the connection is observed as it
/// answered, not as a broken pipe on the client's side.
fn raw_post_status(url: &str, path: &str, headers: &[(&str, &str)], body: Vec<u8>) -> u16 {
    use std::io::{Read, Write};
    let addr = url.strip_prefix("http://").unwrap();
    let mut stream = std::net::TcpStream::connect(addr).unwrap();
    let mut head = format!(
        "POST {path} HTTP/1.1\r\nHost: {addr}\r\nContent-Length: {}\r\nConnection: close\r\n",
        body.len()
    );
    for (k, v) in headers {
        head.push_str(&format!("{k}: {v}\r\n"));
    }
    head.push_str("\r\n");
    stream.write_all(head.as_bytes()).unwrap();
    let mut writer = stream.try_clone().unwrap();
    let sender = std::thread::spawn(move || {
        let _ = writer.write_all(&body);
    });
    let mut response = Vec::new();
    let mut buf = [0u8; 4096];
    while !response.windows(2).any(|w| w == b"\r\n") {
        match stream.read(&mut buf) {
            Ok(0) | Err(_) => break,
            Ok(n) => response.extend_from_slice(&buf[..n]),
        }
    }
    let _ = stream.shutdown(std::net::Shutdown::Both);
    let _ = sender.join();
    let line = String::from_utf8_lossy(&response);
    line.split_whitespace()
        .nth(1)
        .and_then(|c| c.parse().ok())
        .unwrap_or_else(|| panic!("no status line: {line}"))
}

struct Api {
    url: String,
    http: reqwest::Client,
}

impl Api {
    async fn submit(&self, bundle: Vec<u8>, settings: &str, token: Option<&str>) -> (StatusCode, Value) {
        let form = Form::new()
            .part("bundle", Part::bytes(bundle).file_name("b.tar"))
            .text("settings", settings.to_string());
        let mut r = self.http.post(format!("{}/api/jobs", self.url)).multipart(form);
        if let Some(t) = token {
            r = r.bearer_auth(t);
        }
        let resp = r.send().await.unwrap();
        let status = resp.status();
        let body = resp.json().await.unwrap_or(Value::Null);
        (status, body)
    }

    async fn call(&self, method: reqwest::Method, path: &str, body: Vec<u8>) -> (StatusCode, Value) {
        self.call_keyed(method, path, body, "").await
    }

    /// A call carrying a lease's secret.
    async fn call_keyed(
        &self,
        method: reqwest::Method,
        path: &str,
        body: Vec<u8>,
        key: &str,
    ) -> (StatusCode, Value) {
        let resp = self
            .http
            .request(method, format!("{}{path}", self.url))
            .bearer_auth(TOKEN)
            .header("x-photonfarm-lease-key", key)
            .body(body)
            .send()
            .await
            .unwrap();
        let status = resp.status();
        (status, resp.json().await.unwrap_or(Value::Null))
    }
}

fn error_of(v: &Value) -> &str {
    v["error"]
        .as_str()
        .unwrap_or_else(|| panic!("not a JSON error: {v}"))
}

#[tokio::test(flavor = "multi_thread")]
async fn bad_requests_get_the_right_4xx_and_the_service_keeps_serving() {
    let dir = tempfile::tempdir().unwrap();
    let (_coordinator, url) = serve(&dir.path().join("data"));
    let api = Api {
        url: url.clone(),
        http: reqwest::Client::new(),
    };
    let cbox = std::fs::read(refs().join("cbox.xml")).unwrap();
    let good = tar_of(&[("cbox.xml", &cbox)]);
    let ok_settings = r#"{"passes": 2, "defines": [["res", "8"]]}"#;

    // Wrong or missing token.
    let multipart = [("Content-Type", "multipart/form-data; boundary=xyz")];
    assert_eq!(raw_post_status(&url, "/api/jobs", &multipart, good.clone()), 401);
    let wrong = [
        ("Content-Type", "multipart/form-data; boundary=xyz"),
        ("Authorization", "Bearer wrong"),
    ];
    assert_eq!(raw_post_status(&url, "/api/jobs", &wrong, good.clone()), 401);
    let (s, v) = api.call(reqwest::Method::GET, "/api/jobs", vec![]).await;
    assert_eq!(s, StatusCode::OK, "{v}");
    let r = reqwest::get(format!("{url}/healthz")).await.unwrap();
    assert_eq!(
        r.status(),
        StatusCode::UNAUTHORIZED,
        "every request needs the token"
    );

    // Malformed scene: the loader's message, with the file named as in the bundle.
    let (s, v) = api
        .submit(
            tar_of(&[("bad.xml", b"<scene version=\"3.0.0\">\n<shape>")]),
            ok_settings,
            Some(TOKEN),
        )
        .await;
    assert_eq!(s, StatusCode::UNPROCESSABLE_ENTITY);
    assert!(
        error_of(&v).starts_with("bad.xml:") && error_of(&v).contains("malformed XML"),
        "{v}"
    );

    // A scene whose mesh is missing.
    let text = String::from_utf8(cbox.clone()).unwrap().replace(
        "</scene>",
        "<shape type=\"obj\"><string name=\"filename\" value=\"gone.obj\"/></shape></scene>",
    );
    let (s, v) = api
        .submit(tar_of(&[("cbox.xml", text.as_bytes())]), ok_settings, Some(TOKEN))
        .await;
    assert_eq!(s, StatusCode::UNPROCESSABLE_ENTITY);
    assert!(error_of(&v).contains("not found"), "{v}");
    assert!(
        !error_of(&v).contains(dir.path().to_str().unwrap()),
        "the coordinator's paths leak: {v}"
    );

    // Path traversal in the bundle.
    let (s, v) = api
        .submit(raw_tar_entry("../evil.xml"), ok_settings, Some(TOKEN))
        .await;
    assert_eq!(s, StatusCode::BAD_REQUEST);
    assert!(error_of(&v).contains("../evil.xml"), "{v}");
    assert!(!dir.path().join("data/evil.xml").exists() && !dir.path().join("evil.xml").exists());

    // Oversized upload (the limit is 1 MiB here).
    let big = tar_of(&[("cbox.xml", &cbox), ("padding.bin", &vec![7u8; 2 << 20])]);
    let mut body =
        b"--xyz\r\nContent-Disposition: form-data; name=\"bundle\"; filename=\"b.tar\"\r\n\r\n".to_vec();
    body.extend_from_slice(&big);
    body.extend_from_slice(b"\r\n--xyz--\r\n");
    let authed = [
        ("Content-Type", "multipart/form-data; boundary=xyz"),
        ("Authorization", "Bearer s3cret-token"),
    ];
    assert_eq!(raw_post_status(&url, "/api/jobs", &authed, body), 413);

    // Garbage JSON, unknown settings, bad values.
    let (s, v) = api.submit(good.clone(), "{not json", Some(TOKEN)).await;
    assert_eq!(s, StatusCode::BAD_REQUEST);
    assert!(error_of(&v).contains("malformed JSON"), "{v}");
    let (s, _) = api.submit(good.clone(), r#"{"pases": 3}"#, Some(TOKEN)).await;
    assert_eq!(s, StatusCode::BAD_REQUEST);
    let (s, v) = api
        .submit(
            good.clone(),
            r#"{"integrator": "sppm", "alpha": 2.0}"#,
            Some(TOKEN),
        )
        .await;
    assert_eq!(s, StatusCode::UNPROCESSABLE_ENTITY);
    assert!(error_of(&v).contains("alpha"), "{v}");
    let (s, v) = api
        .call(reqwest::Method::POST, "/api/lease", b"garbage".to_vec())
        .await;
    assert_eq!(s, StatusCode::BAD_REQUEST);
    error_of(&v);

    // Unknown things.
    let (s, v) = api.call(reqwest::Method::GET, "/api/jobs/999", vec![]).await;
    assert_eq!(s, StatusCode::NOT_FOUND);
    error_of(&v);
    let (s, _) = api.call(reqwest::Method::GET, "/api/jobs/abc", vec![]).await;
    assert_eq!(s, StatusCode::NOT_FOUND);
    let (s, _) = api.call(reqwest::Method::GET, "/nowhere", vec![]).await;
    assert_eq!(s, StatusCode::NOT_FOUND);
    let (s, _) = api
        .call(reqwest::Method::PUT, "/api/leases/12345/result", b"x".to_vec())
        .await;
    assert_eq!(s, StatusCode::CONFLICT);

    // Still serving: a good job is accepted, leased, and a garbage result for its live lease
    // is refused without harm.
    let (s, v) = api.submit(good.clone(), ok_settings, Some(TOKEN)).await;
    assert_eq!(s, StatusCode::CREATED, "{v}");
    let (s, lease) = api
        .call(
            reqwest::Method::POST,
            "/api/lease",
            br#"{"worker": "w", "threads": 1}"#.to_vec(),
        )
        .await;
    assert_eq!(s, StatusCode::OK, "{lease}");
    let lease_id = lease["lease_id"].as_u64().unwrap();
    let (s, v) = api
        .call(
            reqwest::Method::PUT,
            &format!("/api/leases/{lease_id}/result"),
            b"garbage".to_vec(),
        )
        .await;
    assert_eq!(
        s,
        StatusCode::FORBIDDEN,
        "only the lease's worker may complete it: {v}"
    );
    let key = lease["key"].as_str().unwrap();
    let (s, v) = api
        .call_keyed(
            reqwest::Method::PUT,
            &format!("/api/leases/{lease_id}/result"),
            b"garbage".to_vec(),
            key,
        )
        .await;
    assert_eq!(s, StatusCode::BAD_REQUEST);
    error_of(&v);
    let (s, v) = api.call(reqwest::Method::GET, "/healthz", vec![]).await;
    assert_eq!(s, StatusCode::OK, "{v}");

    // Cancelling: the job says so, its lease is dead, and no more work is handed out for it.
    let job = v_id(&api).await;
    let (s, lease) = api
        .call(
            reqwest::Method::POST,
            "/api/lease",
            br#"{"worker": "w2", "threads": 1}"#.to_vec(),
        )
        .await;
    assert_eq!(s, StatusCode::OK, "{lease}");
    let (s, v) = api
        .call(reqwest::Method::DELETE, &format!("/api/jobs/{job}"), vec![])
        .await;
    assert_eq!(s, StatusCode::OK, "{v}");
    assert_eq!(v["state"], "cancelled");
    let lease_id = lease["lease_id"].as_u64().unwrap();
    let (s, _) = api
        .call(
            reqwest::Method::POST,
            &format!("/api/leases/{lease_id}/heartbeat"),
            vec![],
        )
        .await;
    assert_eq!(s, StatusCode::CONFLICT, "a cancelled job's lease is void");
    let (s, _) = api
        .call(
            reqwest::Method::GET,
            &format!("/api/jobs/{job}/image.exr"),
            vec![],
        )
        .await;
    assert_eq!(s, StatusCode::NOT_FOUND, "nothing was rendered");
}

/// The newest job's id.
async fn v_id(api: &Api) -> u64 {
    let (_, v) = api.call(reqwest::Method::GET, "/api/jobs", vec![]).await;
    v["jobs"].as_array().unwrap().last().unwrap()["id"]
        .as_u64()
        .unwrap()
}

/// Every route of `photonfarm::protocol::routes` reaches a handler of the coordinator's router
/// (none falls through to "no such endpoint"), and the workers' routes take only the workers'
/// token: the router driven in process, as axum's examples test handlers.
#[tokio::test]
async fn every_protocol_route_is_served_and_guarded_by_its_token() {
    use axum::body::Body;
    use axum::http::{Request, header};
    use coordinator::service::{self, admission::Admission, api::Tokens, farm::FarmConfig};
    use photonfarm::protocol::routes;
    use tower::ServiceExt;

    let dir = tempfile::tempdir().unwrap();
    let config = service::ServeConfig {
        data: dir.path().to_path_buf(),
        tokens: Tokens {
            client: Some("client".into()),
            worker: Some("worker".into()),
        },
        admission: Admission::for_memory(1 << 30),
        checker: None,
        farm: FarmConfig {
            limits: photonfarm::limits::Limits::for_memory(1 << 30),
            ..FarmConfig::default()
        },
    };
    let app = service::api::router(service::open(&config).await.unwrap());
    let call = |method: &str, path: String, token: &str| {
        let request = Request::builder()
            .method(method)
            .uri(path)
            .header(header::AUTHORIZATION, format!("Bearer {token}"))
            .header(header::CONTENT_TYPE, "application/json")
            .body(Body::from(r#"{"worker": "w", "threads": 1}"#))
            .unwrap();
        let app = app.clone();
        async move {
            let response = app.oneshot(request).await.unwrap();
            let status = response.status();
            let body = axum::body::to_bytes(response.into_body(), 1 << 20).await.unwrap();
            (status, String::from_utf8_lossy(&body).into_owned())
        }
    };
    let users = [
        ("GET", routes::HEALTH.to_string()),
        ("GET", routes::METRICS.to_string()),
        ("GET", routes::JOBS.to_string()),
        ("POST", routes::JOBS.to_string()),
        ("GET", routes::job(1)),
        ("DELETE", routes::job(1)),
        ("GET", format!("{}/noise", routes::job(1))),
        ("GET", routes::job_file(1, "image.exr")),
        ("GET", routes::WORKERS.to_string()),
    ];
    let workers = [
        ("POST", routes::lease(0)),
        ("POST", routes::heartbeat(5)),
        ("PUT", routes::result(5)),
        ("POST", routes::release(5)),
        ("GET", routes::bundle("ab")),
    ];
    for (token, list, other) in [
        ("client", &users[..], "worker"),
        ("worker", &workers[..], "client"),
    ] {
        for (method, path) in list {
            let (status, body) = call(method, path.clone(), token).await;
            assert!(
                !body.contains("no such endpoint"),
                "{method} {path}: {status} {body}"
            );
            assert_ne!(status, StatusCode::UNAUTHORIZED, "{method} {path}: {body}");
            if path != routes::HEALTH {
                let (status, body) = call(method, path.clone(), other).await;
                assert_eq!(
                    status,
                    StatusCode::UNAUTHORIZED,
                    "{method} {path} with the {other} token: {body}"
                );
            }
        }
    }
    let (status, _) = call("GET", "/api/nothing".into(), "client").await;
    assert_eq!(status, StatusCode::NOT_FOUND);
}
