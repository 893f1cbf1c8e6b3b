//! Shared helpers of the integration tests: start the real server binary on 127.0.0.1:0 and talk
//! HTTP/1.1 to it.
#![allow(dead_code)]

use std::io::{BufRead, BufReader, Read};
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use http_body_util::{BodyExt, Full};
use hyper::body::Bytes;
use hyper_util::rt::TokioIo;
use serde_json::Value;

pub fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

pub fn datasets() -> PathBuf {
    repo().join("..").join("shared").join("datasets")
}

/// A fresh scratch directory under the system temp dir (`multifit-<tag>-XXXXXX`), removed with
/// everything in it when dropped; it dereferences to its path.
pub struct Scratch(tempfile::TempDir);

impl Scratch {
    pub fn new(tag: &str) -> Scratch {
        Scratch(
            tempfile::Builder::new()
                .prefix(&format!("multifit-{tag}-"))
                .tempdir()
                .expect("create a scratch directory"),
        )
    }
}

impl std::ops::Deref for Scratch {
    type Target = Path;
    fn deref(&self) -> &Path {
        self.0.path()
    }
}

impl AsRef<Path> for Scratch {
    fn as_ref(&self) -> &Path {
        self.0.path()
    }
}

/// A running `multifit-server` process, killed on drop.
pub struct Server {
    pub addr: SocketAddr,
    pub child: Child,
    stderr: Option<std::thread::JoinHandle<String>>,
}

impl Server {
    /// Starts the server with the shipped models and extra flags; waits until it is ready.
    pub fn start(extra: &[&str]) -> Server {
        let models = repo().join("models");
        Self::start_with_models(&models, extra)
    }

    pub fn start_with_models(models: &Path, extra: &[&str]) -> Server {
        let mut child = Command::new(env!("CARGO_BIN_EXE_multifit-server"))
            .arg("--addr")
            .arg("127.0.0.1:0")
            .arg("--models")
            .arg(models)
            .args(extra)
            .env("RUST_LOG", "warn")
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("start multifit-server");
        let stderr = child.stderr.take().expect("stderr");
        let stderr = std::thread::spawn(move || {
            let mut s = String::new();
            let _ = BufReader::new(stderr).read_to_string(&mut s);
            s
        });
        let mut line = String::new();
        BufReader::new(child.stdout.take().expect("stdout"))
            .read_line(&mut line)
            .expect("read stdout");
        let addr = line
            .trim()
            .rsplit("http://")
            .next()
            .and_then(|a| a.parse().ok())
            .unwrap_or_else(|| panic!("no address announced: {line:?}"));
        let server = Server {
            addr,
            child,
            stderr: Some(stderr),
        };
        let deadline = Instant::now() + Duration::from_secs(30);
        while Instant::now() < deadline {
            if let Ok((200, _)) = server.try_get("/health/ready") {
                return server;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        panic!("server did not become ready");
    }

    fn try_get(&self, path: &str) -> Result<(u16, Value), String> {
        let r = send(self.addr, "GET", path, None, Vec::new())?;
        Ok((r.status, r.json()))
    }

    pub fn get(&self, path: &str) -> Response {
        send(self.addr, "GET", path, None, Vec::new()).expect("GET")
    }

    pub fn post_json(&self, path: &str, body: &Value) -> Response {
        self.post_raw(
            path,
            Some("application/json"),
            serde_json::to_vec(body).unwrap(),
        )
    }

    pub fn post_raw(&self, path: &str, content_type: Option<&str>, body: Vec<u8>) -> Response {
        send(self.addr, "POST", path, content_type, body).expect("POST")
    }

    /// Sends SIGTERM and waits for the exit status; returns (status code, stderr).
    pub fn terminate(mut self) -> (Option<i32>, String) {
        let pid = self.child.id().to_string();
        Command::new("kill")
            .args(["-TERM", &pid])
            .status()
            .expect("kill");
        let status = self.child.wait().expect("wait");
        let stderr = self
            .stderr
            .take()
            .map(|h| h.join().unwrap_or_default())
            .unwrap_or_default();
        (status.code(), stderr)
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// An HTTP answer.
pub struct Response {
    pub status: u16,
    pub headers: hyper::HeaderMap,
    pub body: Vec<u8>,
}

impl Response {
    pub fn json(&self) -> Value {
        serde_json::from_slice(&self.body).unwrap_or(Value::Null)
    }
    pub fn text(&self) -> String {
        String::from_utf8_lossy(&self.body).into_owned()
    }
    /// The error code of an error answer (panics when the body is not the error shape).
    pub fn error_code(&self) -> String {
        let v = self.json();
        let code = v["error"]["code"]
            .as_str()
            .unwrap_or_else(|| panic!("not an error body: {}", self.text()));
        assert!(
            v["error"]["message"].is_string(),
            "error without message: {v}"
        );
        code.to_string()
    }
}

/// One HTTP/1.1 request over a fresh connection.
pub fn send(
    addr: SocketAddr,
    method: &str,
    path: &str,
    content_type: Option<&str>,
    body: Vec<u8>,
) -> Result<Response, String> {
    let headers: Vec<(&str, &str)> = content_type
        .map(|ct| ("content-type", ct))
        .into_iter()
        .collect();
    send_with(addr, method, path, &headers, body)
}

/// One HTTP/1.1 request with the given headers over a fresh connection.
pub fn send_with(
    addr: SocketAddr,
    method: &str,
    path: &str,
    headers: &[(&str, &str)],
    body: Vec<u8>,
) -> Result<Response, String> {
    let headers: Vec<(String, String)> = headers
        .iter()
        .map(|(k, v)| (k.to_string(), v.to_string()))
        .collect();
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(|e| e.to_string())?;
    rt.block_on(async move {
        let stream = tokio::net::TcpStream::connect(addr)
            .await
            .map_err(|e| e.to_string())?;
        let (mut sender, conn) = hyper::client::conn::http1::handshake(TokioIo::new(stream))
            .await
            .map_err(|e| e.to_string())?;
        tokio::spawn(conn);
        let mut req = hyper::Request::builder()
            .method(method)
            .uri(path)
            .header("host", addr.to_string());
        for (name, value) in &headers {
            req = req.header(name.as_str(), value.as_str());
        }
        let req = req
            .body(Full::new(Bytes::from(body)))
            .map_err(|e| e.to_string())?;
        let res = sender.send_request(req).await.map_err(|e| e.to_string())?;
        let status = res.status().as_u16();
        let headers = res.headers().clone();
        let body = res
            .into_body()
            .collect()
            .await
            .map_err(|e| e.to_string())?
            .to_bytes()
            .to_vec();
        Ok(Response {
            status,
            headers,
            body,
        })
    })
}

/// The `multifit_queue_depth` gauge: fit requests admitted and not yet answered (body being
/// read, waiting for a worker or running); `None` when `/metrics` cannot be read.
pub fn queue_depth(addr: SocketAddr) -> Option<i64> {
    let r = send(addr, "GET", "/metrics", None, Vec::new()).ok()?;
    r.text()
        .lines()
        .find_map(|l| l.strip_prefix("multifit_queue_depth "))
        .and_then(|v| v.trim().parse().ok())
}

/// Waits until the server has admitted exactly `n` fit requests, at most `limit`: a test that
/// needs requests in flight waits for them instead of sleeping for a guessed time, which a
/// loaded machine can overrun.
pub fn wait_queue_depth(addr: SocketAddr, n: i64, limit: Duration) {
    let deadline = Instant::now() + limit;
    loop {
        let depth = queue_depth(addr);
        if depth == Some(n) {
            return;
        }
        assert!(
            Instant::now() < deadline,
            "{n} fit requests not admitted within {limit:?} (queue depth {depth:?})"
        );
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// A dataset sequence file as JSON.
pub fn dataset(rel: &str) -> Value {
    let path = datasets().join(rel);
    serde_json::from_slice(
        &std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display())),
    )
    .unwrap()
}

/// Hex SHA-256 of a shipped model's weight files, concatenated in the order its card lists them
/// (`weights.safetensors`, then each member's), read straight from `models/<name>/`.
pub fn shipped_weights_sha256(name: &str) -> String {
    use sha2::{Digest, Sha256};
    let dir = repo().join("models").join(name);
    let card: Value =
        serde_json::from_slice(&std::fs::read(dir.join("model.json")).unwrap()).unwrap();
    // The card's order: its own network, its members', its network for sparse sets.
    let members = card["members"].as_array().cloned().unwrap_or_default();
    let sparse = card.get("sparse").cloned();
    let files = std::iter::once(multifit::registry::WEIGHTS_FILE.to_string())
        .chain(
            members
                .iter()
                .map(|m| m["weights"].as_str().unwrap().to_string()),
        )
        .chain(sparse.map(|s| s["weights"].as_str().unwrap().to_string()));
    let mut hasher = Sha256::new();
    for file in files {
        hasher.update(std::fs::read(dir.join(file)).unwrap());
    }
    format!("{:x}", hasher.finalize())
}

/// A fit answer's `embeddings`, one row per point.
pub fn embeddings(v: &Value) -> Vec<Vec<f64>> {
    v["embeddings"]
        .as_array()
        .expect("embeddings")
        .iter()
        .map(|row| {
            row.as_array()
                .expect("an embedding row")
                .iter()
                .map(|x| x.as_f64().unwrap())
                .collect()
        })
        .collect()
}

/// A fit answer's labels, outliers (-1) as one more group labelled k, as scoring counts them.
pub fn labels(v: &Value) -> Vec<usize> {
    let k = v["k"].as_u64().expect("k") as usize;
    v["labels"]
        .as_array()
        .expect("labels")
        .iter()
        .map(|l| usize::try_from(l.as_i64().expect("integer label")).unwrap_or(k))
        .collect()
}

/// Ground-truth labels of a dataset file, renumbered 0..K.
pub fn truth(v: &Value) -> Vec<usize> {
    let raw: Vec<i64> = v["labels"]
        .as_array()
        .unwrap()
        .iter()
        .map(|l| l.as_i64().unwrap())
        .collect();
    multifit::data::dataset::renumber(&raw).0
}

/// The body of a points2d fit of `4 * per_shape` generated LCE points (one line, one circle, two
/// ellipses; generator `seed`) with silhouette selection, and its point count: a fit slow enough
/// (the lce model's neighbour features and the silhouette grow with N) to still be running while
/// a test loads or signals the server.
pub fn slow_fit_body(seed: u64, per_shape: usize, extra: &[(&str, Value)]) -> (Vec<u8>, usize) {
    use multifit::data::synthetic::{LceConfig, LceGenerator, LceVariant};
    let s = LceGenerator::new(
        seed,
        LceConfig {
            points_per_shape: per_shape,
            noise: 0.05,
            ..LceConfig::default()
        },
    )
    .sample(LceVariant::Mixed, "slow")
    .sample;
    let rows: Vec<Vec<f64>> = (0..s.points.len())
        .map(|i| s.points.row(i).to_vec())
        .collect();
    let mut body =
        serde_json::json!({"kind": "points2d", "points": rows, "selection": "silhouette"});
    for (key, value) in extra {
        body[*key] = value.clone();
    }
    (serde_json::to_vec(&body).unwrap(), rows.len())
}

/// Flags of a tiny network that trains in seconds.
pub const TINY: [&str; 10] = [
    "--width",
    "16",
    "--depth",
    "1",
    "--embed-dim",
    "4",
    "--epochs",
    "2",
    "--lr",
    "1e-3",
];

/// Runs `multifit-train` with `args` on one thread.
pub fn run(args: &[&str]) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_multifit-train"))
        .args(args)
        .env("RAYON_NUM_THREADS", "1")
        .output()
        .expect("run multifit-train")
}

/// Runs `multifit-train` with `args`, which must succeed; its standard output.
pub fn ok(args: &[&str]) -> String {
    let out = run(args);
    assert!(
        out.status.success(),
        "{args:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}
