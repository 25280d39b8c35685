//! A client of the coordinator's API with separate client and worker tokens, and the small
//! scenes and bundles the robustness tests submit: shared by `robust.rs` and `latency.rs` (the
//! latter is its own test binary, so that nothing else competes for the CPU while it measures).

use std::path::Path;

use reqwest::StatusCode;
use reqwest::multipart::{Form, Part};
use serde_json::Value;

pub const TOKEN: &str = "client-token";
pub const WORKER_TOKEN: &str = "worker-token";

pub fn tar_of(files: &[(&str, &[u8])]) -> Vec<u8> {
    let mut b = tar::Builder::new(Vec::new());
    for (name, data) in files {
        let mut h = tar::Header::new_gnu();
        h.set_size(data.len() as u64);
        h.set_mode(0o644);
        h.set_cksum();
        b.append_data(&mut h, name, *data).unwrap();
    }
    b.into_inner().unwrap()
}

/// A small scene with `integrator` and `film` inserted.
pub fn scene(integrator: &str, width: u64, height: u64) -> Vec<u8> {
    format!(
        r#"<scene version="3.0.0">
        {integrator}
        <sensor type="perspective"><float name="fov" value="60"/>
            <transform name="to_world"><lookat origin="0,0,3" target="0,0,0" up="0,1,0"/></transform>
            <film type="hdrfilm"><integer name="width" value="{width}"/><integer name="height" value="{height}"/>
                <rfilter type="box"/></film></sensor>
        <shape type="sphere"><float name="radius" value="0.8"/><bsdf type="diffuse"/></shape>
        <emitter type="point"><point name="position" x="0" y="2" z="2"/><rgb name="intensity" value="5"/></emitter>
        </scene>"#
    )
    .into_bytes()
}

pub fn serve(data: &Path, bind: &str, extra: &[&str]) -> (super::Proc, String) {
    super::serve(
        data,
        bind,
        extra,
        &[
            ("PHOTONFARM_TOKEN", TOKEN),
            ("PHOTONFARM_WORKER_TOKEN", WORKER_TOKEN),
        ],
    )
}

pub struct Api {
    pub url: String,
    pub http: reqwest::Client,
}

impl Api {
    pub fn new(url: &str) -> Api {
        Api {
            url: url.to_string(),
            http: reqwest::Client::new(),
        }
    }

    pub async fn submit_form(&self, form: Form) -> (StatusCode, Value) {
        let resp = self
            .http
            .post(format!("{}/api/jobs", self.url))
            .bearer_auth(TOKEN)
            .multipart(form)
            .send()
            .await
            .unwrap();
        let status = resp.status();
        (status, resp.json().await.unwrap_or(Value::Null))
    }

    pub async fn submit(&self, bundle: Vec<u8>, settings: &str) -> (StatusCode, Value) {
        let form = Form::new()
            .part("bundle", Part::bytes(bundle).file_name("b.tar"))
            .text("settings", settings.to_string());
        self.submit_form(form).await
    }

    pub async fn call(
        &self,
        method: reqwest::Method,
        path: &str,
        token: &str,
        key: &str,
        body: Vec<u8>,
    ) -> (StatusCode, Value) {
        let resp = self
            .http
            .request(method, format!("{}{path}", self.url))
            .header("Authorization", format!("Bearer {token}"))
            .header("x-photonfarm-lease-key", key)
            .body(body)
            .send()
            .await
            .unwrap();
        let status = resp.status();
        (status, resp.json().await.unwrap_or(Value::Null))
    }

    pub async fn get(&self, path: &str) -> (StatusCode, Value) {
        self.call(reqwest::Method::GET, path, TOKEN, "", vec![]).await
    }

    pub async fn lease(&self, worker: &str) -> Option<Value> {
        let body = format!(r#"{{"worker": "{worker}", "threads": 1}}"#).into_bytes();
        let (s, v) = self
            .call(reqwest::Method::POST, "/api/lease", WORKER_TOKEN, "", body)
            .await;
        match s {
            StatusCode::OK => Some(v),
            StatusCode::NO_CONTENT => None,
            s => panic!("lease: {s} {v}"),
        }
    }
}
