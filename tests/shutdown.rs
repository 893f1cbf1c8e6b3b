//! SIGTERM under load. In-flight requests (running, queued for a worker, and a batch)
//! complete with full answers; once the signal is handled new connections are refused (or
//! answered 503) while the drain is still going on; idle and silent connections do not hold the
//! process; it exits 0.
//!
//! tests/server.rs (`sigterm_drains_in_flight_requests_and_exits_zero`) already covers one
//! in-flight request, exit 0 and refusal after the exit; this file covers several concurrent and
//! queued requests, the answers' contents, refusal during the drain, keep-alive and silent
//! connections, repeated signals and SIGINT.

mod common;

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::process::{Command, ExitStatus};
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use common::{Server, labels, send, wait_queue_depth};
use serde_json::{Value, json};

fn signal(pid: u32, sig: &str) {
    let ok = Command::new("kill")
        .args([sig, &pid.to_string()])
        .status()
        .expect("run kill")
        .success();
    assert!(ok, "kill {sig} {pid}");
}

/// Waits for the child to exit, at most `limit`.
fn wait_exit(server: &mut Server, limit: Duration) -> Option<ExitStatus> {
    let deadline = Instant::now() + limit;
    while Instant::now() < deadline {
        if let Some(status) = server.child.try_wait().expect("try_wait") {
            return Some(status);
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    None
}

/// An HTTP/1.1 keep-alive connection that has completed one request and stays open, idle.
fn idle_keep_alive(addr: SocketAddr) -> TcpStream {
    let mut s = TcpStream::connect(addr).expect("connect");
    s.write_all(format!("GET /health/live HTTP/1.1\r\nhost: {addr}\r\n\r\n").as_bytes())
        .unwrap();
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    let mut got = Vec::new();
    let mut buf = [0u8; 4096];
    // The answer is small: read until the JSON body's closing brace.
    while !got.ends_with(b"}") {
        let n = s.read(&mut buf).expect("read keep-alive answer");
        assert!(n > 0, "server closed the keep-alive connection early");
        got.extend_from_slice(&buf[..n]);
    }
    let text = String::from_utf8_lossy(&got);
    assert!(text.starts_with("HTTP/1.1 200"), "{text}");
    s
}

/// True when the server closed `s` (EOF or reset) within the stream's read timeout.
fn closed_by_server(s: &mut TcpStream) -> bool {
    let mut buf = [0u8; 256];
    match s.read(&mut buf) {
        Ok(0) => true,
        Ok(_) => false,
        Err(e) => !matches!(
            e.kind(),
            std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
        ),
    }
}

#[test]
fn sigterm_under_load_completes_in_flight_refuses_new_and_exits_zero() {
    let started = Instant::now();
    // Two workers, five concurrent fits and a batch: two run, the rest wait in the queue. The
    // request timeout is far beyond the drain, so that a loaded machine (seven fits of 4800
    // points, one after another on each worker) cannot turn a queued fit into a 503.
    let mut server = Server::start(&["--workers", "2", "--request-timeout-ms", "600000"]);
    let addr = server.addr;
    let (body, n) = common::slow_fit_body(5, 1200, &[("seed", json!(9))]);

    // Reference answer before any load: same input and seed, same labels.
    let t = Instant::now();
    let reference = server.post_raw("/v1/fit", Some("application/json"), body.clone());
    let one_fit = t.elapsed();
    assert_eq!(reference.status, 200, "reference fit: {}", reference.text());
    let reference = labels(&reference.json());
    assert_eq!(reference.len(), n);
    eprintln!("one fit of {n} points: {one_fit:?}");

    // Connections that must not keep the server alive: an idle keep-alive one and one that
    // never sends a byte.
    let mut keep_alive = idle_keep_alive(addr);
    let mut silent = TcpStream::connect(addr).expect("connect silent");
    silent
        .set_read_timeout(Some(Duration::from_secs(20)))
        .unwrap();

    const FITS: usize = 5;
    let done = Arc::new(AtomicUsize::new(0));
    let mut clients = Vec::new();
    for _ in 0..FITS {
        let (body, done) = (body.clone(), done.clone());
        clients.push(std::thread::spawn(move || {
            let r = send(addr, "POST", "/v1/fit", Some("application/json"), body);
            done.fetch_add(1, Ordering::SeqCst);
            r
        }));
    }
    let batch = {
        let entry: Value = serde_json::from_slice(&body).unwrap();
        let b = serde_json::to_vec(&json!({"requests": [entry.clone(), entry]})).unwrap();
        let done = done.clone();
        std::thread::spawn(move || {
            let r = send(addr, "POST", "/v1/fit/batch", Some("application/json"), b);
            done.fetch_add(1, Ordering::SeqCst);
            r
        })
    };
    // Every request is in flight once all of them are admitted (the batch admits one entry at
    // a time): the fits and the batch's first entry.
    wait_queue_depth(addr, FITS as i64 + 1, Duration::from_secs(20));
    assert_eq!(
        done.load(Ordering::SeqCst),
        0,
        "no answer before the signal (the fits are too fast for this test)"
    );

    let pid = server.child.id();
    signal(pid, "-TERM");
    let signalled = Instant::now();

    // New connections: refused (or 503) once the signal is handled, while the drain goes on.
    let mut refused_while_draining = None;
    let deadline = signalled + Duration::from_secs(5);
    while Instant::now() < deadline {
        match send(addr, "GET", "/health/ready", None, Vec::new()) {
            Err(_) => {
                refused_while_draining = Some(done.load(Ordering::SeqCst));
                break;
            }
            Ok(r) if r.status == 503 => {
                assert_eq!(r.error_code(), "not_ready", "503 while draining");
                refused_while_draining = Some(done.load(Ordering::SeqCst));
                break;
            }
            Ok(r) => assert_eq!(r.status, 200, "ready before the signal is handled"),
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    let answered_then =
        refused_while_draining.expect("new connections still served 5 s after SIGTERM");
    assert!(
        answered_then < FITS + 1,
        "refusal must be observed while requests are still in flight ({answered_then} answered)"
    );
    eprintln!(
        "refused {:?} after SIGTERM, {answered_then} of {} in-flight answered",
        signalled.elapsed(),
        FITS + 1
    );
    // A second SIGTERM during the drain changes nothing.
    signal(pid, "-TERM");
    // Refused from then on: new fits and probes get no 200.
    for path in ["/v1/fit", "/health/live"] {
        let r = if path == "/v1/fit" {
            send(addr, "POST", path, Some("application/json"), body.clone())
        } else {
            send(addr, "GET", path, None, Vec::new())
        };
        if let Ok(r) = r {
            assert_eq!(
                r.status,
                503,
                "new request to {path} after SIGTERM: {}",
                r.text()
            );
        }
    }

    // Every in-flight request completes with a full, correct answer.
    for (i, c) in clients.into_iter().enumerate() {
        let r = c
            .join()
            .unwrap()
            .unwrap_or_else(|e| panic!("in-flight fit {i} got no answer: {e}"));
        assert_eq!(r.status, 200, "in-flight fit {i}: {}", r.text());
        let v = r.json();
        assert_eq!(
            labels(&v),
            reference,
            "in-flight fit {i}: same labels as the reference"
        );
        assert_eq!(v["selection"], "silhouette", "in-flight fit {i}");
        assert!(
            !v["residuals"].as_array().unwrap().is_empty(),
            "in-flight fit {i}"
        );
    }
    let r = batch
        .join()
        .unwrap()
        .unwrap_or_else(|e| panic!("in-flight batch got no answer: {e}"));
    assert_eq!(r.status, 200, "in-flight batch: {}", r.text());
    let results = r.json()["results"].as_array().cloned().expect("results");
    assert_eq!(results.len(), 2, "in-flight batch: both entries");
    for (i, v) in results.iter().enumerate() {
        assert_eq!(labels(v), reference, "in-flight batch entry {i}: {v}");
    }
    let drained = signalled.elapsed();

    // It exits 0, promptly, with the idle and silent connections still open on our side.
    let status = wait_exit(&mut server, Duration::from_secs(15))
        .expect("the server did not exit within 15 s of the last in-flight answer");
    assert_eq!(
        status.code(),
        Some(0),
        "exit status after SIGTERM: {status:?}"
    );
    assert!(
        closed_by_server(&mut keep_alive),
        "idle keep-alive connection closed"
    );
    assert!(closed_by_server(&mut silent), "silent connection closed");
    assert!(
        TcpStream::connect(addr).is_err(),
        "nothing listens after the exit"
    );
    eprintln!(
        "drained in {drained:?}, exited {:?} after the signal; test took {:?}",
        signalled.elapsed(),
        started.elapsed()
    );
}

#[test]
fn sigint_and_repeated_sigterm_on_an_idle_server_exit_zero() {
    for signals in [&["-INT"][..], &["-TERM", "-TERM", "-TERM"][..]] {
        let mut server = Server::start(&[]);
        let _keep_alive = idle_keep_alive(server.addr);
        let t = Instant::now();
        for s in signals {
            signal(server.child.id(), s);
        }
        let status = wait_exit(&mut server, Duration::from_secs(10))
            .unwrap_or_else(|| panic!("{signals:?}: no exit within 10 s"));
        assert_eq!(status.code(), Some(0), "{signals:?}: {status:?}");
        assert!(
            t.elapsed() < Duration::from_secs(5),
            "{signals:?}: exit took {:?}",
            t.elapsed()
        );
    }
}

/// A client that has sent only part of a request (headers without the blank line, or headers
/// and part of a declared body) and stays connected does not keep the server from exiting after
/// SIGTERM: the drain is bounded by the request timeout plus a second.
#[test]
fn a_stalled_partial_request_does_not_block_exit_after_sigterm() {
    let cases: [(&str, &[u8]); 2] = [
        ("partial headers", b"POST /v1/fit HTTP/1.1\r\nhost: x\r\n"),
        (
            "partial body",
            b"POST /v1/fit HTTP/1.1\r\nhost: x\r\ncontent-type: application/json\r\n\
              content-length: 1000\r\n\r\n{\"kind\":",
        ),
    ];
    // Both variants at once, each on its own server, so a failure costs 10 s, not 20.
    let runs: Vec<_> = cases
        .into_iter()
        .map(|(what, partial)| {
            std::thread::spawn(move || {
                let mut server = Server::start(&["--request-timeout-ms", "2000"]);
                let mut stalled = TcpStream::connect(server.addr).expect("connect");
                stalled.write_all(partial).unwrap();
                // Let the server read what was sent.
                std::thread::sleep(Duration::from_millis(200));
                signal(server.child.id(), "-TERM");
                let status = wait_exit(&mut server, Duration::from_secs(10));
                drop(stalled);
                match status {
                    None => Err(format!(
                        "{what}: no exit within 10 s of SIGTERM while a client stalls mid-request"
                    )),
                    Some(s) if s.code() != Some(0) => Err(format!("{what}: exit {s:?}")),
                    Some(_) => Ok(()),
                }
            })
        })
        .collect();
    let failures: Vec<String> = runs
        .into_iter()
        .filter_map(|h| h.join().unwrap().err())
        .collect();
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
